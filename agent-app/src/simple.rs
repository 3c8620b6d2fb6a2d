//! [`App`]: the application of a crate that gives the layer no more than its
//! spec, a build function and an end rule.

use std::process::ExitCode;
use std::time::Duration;

use agent_core::{ExecConfig, System};

use crate::error::{AppError, BoxError};
use crate::watch::{End, Quiet, Watcher};
use crate::{Application, Common, NoFlags, SpecFile, Target};

type Build = Box<dyn FnMut(&Target<'_>) -> Result<System, BoxError>>;

/// An [`Application`] made of a spec (embedded in the program), a function
/// that builds the system for a [`Target`] (the whole spec, or the system of a
/// deployment), an end rule and a time limit. See the crate's example.
pub struct App {
    path: String,
    text: String,
    build: Option<Build>,
    end: End,
    limit: Duration,
    exec: ExecConfig,
}

impl std::fmt::Debug for App {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("App")
            .field("spec", &self.path)
            .field("end", &self.end)
            .field("limit", &self.limit)
            .finish()
    }
}

impl App {
    /// The application of the spec `text` (named `path` in messages and
    /// recordings).
    pub fn new(path: impl Into<String>, text: impl Into<String>) -> App {
        App {
            path: path.into(),
            text: text.into(),
            build: None,
            end: End::Limit,
            limit: Duration::from_secs(10),
            exec: ExecConfig::default(),
        }
    }

    /// How the system is built: for [`Target::Whole`] every component of the
    /// spec, for [`Target::Process`] those of the deployment
    /// ([`Target::deployment`]), which the layer then places.
    pub fn build(
        mut self,
        f: impl FnMut(&Target<'_>) -> Result<System, BoxError> + 'static,
    ) -> App {
        self.build = Some(Box::new(f));
        self
    }

    /// The rule that ends a run before its time limit.
    pub fn ends_when(mut self, end: End) -> App {
        self.end = end;
        self
    }

    /// The time limit when `--for` is not given (10 s unless set).
    pub fn limit(mut self, limit: Duration) -> App {
        self.limit = limit;
        self
    }

    /// The executors' settings (by default they stop on the first error).
    pub fn exec(mut self, exec: ExecConfig) -> App {
        self.exec = exec;
        self
    }

    /// Parse the command line and run: the program's `main`.
    pub fn main(self) -> ExitCode {
        crate::main(self)
    }
}

impl Application for App {
    type Flags = NoFlags;
    type Config = ();
    type Seen = ();

    fn configure(&mut self, _: &NoFlags, _: &Common) -> Result<Vec<()>, AppError> {
        Ok(vec![()])
    }

    fn spec(&self, (): &()) -> Result<SpecFile, AppError> {
        SpecFile::parse(self.path.clone(), self.text.clone())
    }

    fn build(&mut self, (): &(), target: &Target<'_>) -> Result<System, AppError> {
        let build = self.build.as_mut().ok_or_else(|| {
            AppError::invalid("App::build was not given a function that builds the system")
        })?;
        build(target).map_err(AppError::Build)
    }

    fn watcher(&mut self, (): &(), _: &Common) -> Box<dyn Watcher<()>> {
        Box::new(Quiet)
    }

    fn end(&self, (): &()) -> End {
        self.end.clone()
    }

    fn limit(&self, (): &()) -> Duration {
        self.limit
    }

    fn exec(&self, (): &()) -> ExecConfig {
        self.exec
    }
}
