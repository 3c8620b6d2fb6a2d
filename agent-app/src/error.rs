//! Why a run could not be made, and the exit status that says so.

use std::path::PathBuf;
use std::process::ExitCode;

/// How a program built on the layer exits: the conventions of a command-line
/// tool.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Status {
    /// 0: the run succeeded (its judgement passed).
    Success,
    /// 1: the run was made and failed (its judgement, an error during the run,
    /// a stop before its end).
    Failed,
    /// 2: invalid input (the command line, a file, the spec): nothing ran, and
    /// running again cannot help.
    Invalid,
}

impl Status {
    /// The process's exit code.
    pub fn code(self) -> u8 {
        match self {
            Status::Success => 0,
            Status::Failed => 1,
            Status::Invalid => 2,
        }
    }

    /// The worse of two statuses (invalid input over failure over success).
    pub fn and(self, other: Status) -> Status {
        if self.code() >= other.code() {
            self
        } else {
            other
        }
    }
}

impl From<Status> for ExitCode {
    fn from(s: Status) -> ExitCode {
        ExitCode::from(s.code())
    }
}

/// The boxed error an application's hooks may return.
pub type BoxError = Box<dyn std::error::Error + Send + Sync>;

/// Why the layer could not run, or why a run ended in error.
#[derive(Debug, thiserror::Error)]
pub enum AppError {
    /// The command line, a configuration file or the spec is invalid: the
    /// message names the flag, file or field. Exit 2; nothing ran.
    #[error("{0}")]
    Invalid(String),
    /// The system could not be built from the spec and the code.
    #[error("{0}")]
    Build(BoxError),
    /// An executor stopped on an error.
    #[error("{0}")]
    Run(String),
    /// The real-time executor could not start, or a thread of it failed
    /// (typed, for a library caller to match).
    #[error(transparent)]
    RealTime(#[from] agent_core::RtError),
    /// A recording could not be made or finished.
    #[error(transparent)]
    Record(#[from] agent_mcap::RecordError),
    /// A file the layer writes.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS's reason.
        source: std::io::Error,
    },
    /// Joining or running a deployment failed.
    #[cfg(feature = "distributed")]
    #[error(transparent)]
    Member(#[from] agent_zenoh::MemberError),
    /// The launcher could not start a process.
    #[cfg(feature = "distributed")]
    #[error(transparent)]
    Launch(#[from] agent_zenoh::LaunchError),
    /// A process of a deployment cannot listen on its endpoint: another
    /// program holds it.
    #[error("process `{process}` cannot listen on {endpoint}: the address is in use{}", holder.as_ref().map(|h| format!(" (by {h})")).unwrap_or_default())]
    EndpointTaken {
        /// The process.
        process: String,
        /// Its endpoint.
        endpoint: String,
        /// Who holds it, when the OS says (`pid 1234: rex --deployment ...`).
        holder: Option<String>,
    },
}

impl AppError {
    /// An invalid-input error from anything printable.
    pub fn invalid(message: impl std::fmt::Display) -> AppError {
        AppError::Invalid(message.to_string())
    }

    /// The exit status this error ends the program with.
    pub fn status(&self) -> Status {
        match self {
            AppError::Invalid(_) | AppError::Build(_) | AppError::EndpointTaken { .. } => {
                Status::Invalid
            }
            #[cfg(feature = "distributed")]
            AppError::Member(m) => {
                use agent_zenoh::MemberError as M;
                match m {
                    M::UnknownDeployment { .. }
                    | M::UnknownProcess { .. }
                    | M::Zenoh { .. }
                    | M::Credentials { .. }
                    | M::Policy(_) => Status::Invalid,
                    _ => Status::Failed,
                }
            }
            AppError::Record(agent_mcap::RecordError::Create { .. }) => Status::Invalid,
            _ => Status::Failed,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_real_time_error_stays_typed_and_fails_the_run() {
        let e: AppError = agent_core::RtError::Panicked("c1".into()).into();
        assert!(
            matches!(&e, AppError::RealTime(agent_core::RtError::Panicked(t)) if t == "c1"),
            "{e:?}"
        );
        assert_eq!(e.to_string(), "thread `c1` panicked");
        assert_eq!(e.status(), Status::Failed);
    }
}
