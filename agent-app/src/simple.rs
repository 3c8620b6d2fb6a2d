//! [`App`]: the application of a crate that gives the layer no more than its
//! spec (or a system built in code), a build function and an end rule.

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
    /// A system built in code: its spec is exported from it at the start.
    code: Option<Code>,
    build: Option<Build>,
    end: End,
    limit: Duration,
    exec: ExecConfig,
}

/// What [`App::from_code`] adds to the spec exported from the built system.
struct Code {
    name: String,
    /// Deployments, in RON.
    deployments: Vec<String>,
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
            code: None,
            build: None,
            end: End::Limit,
            limit: Duration::from_secs(10),
            exec: ExecConfig::default(),
        }
    }

    /// The application of system `name` built in code by `build`, with no spec
    /// file: its spec is exported from the system built (as
    /// `embodied::spec::export::spec_of` does) and checked as a file would be,
    /// for `check`, `diagram`, recordings and their replay. Every target gets
    /// the whole system `build` makes; [`App::deployment`] adds deployments.
    pub fn from_code(
        name: impl Into<String>,
        mut build: impl FnMut() -> Result<System, BoxError> + 'static,
    ) -> App {
        let name = name.into();
        App {
            path: format!("{name}.ron (exported from the system built in code)"),
            text: String::new(),
            code: Some(Code {
                name,
                deployments: Vec::new(),
            }),
            build: Some(Box::new(move |_: &Target<'_>| build())),
            end: End::Limit,
            limit: Duration::from_secs(10),
            exec: ExecConfig::default(),
        }
    }

    /// A deployment of a system built in code ([`App::from_code`]), in the
    /// spec's RON (`(name: "split", hosts: [...])`, see the spec reference):
    /// each of its processes builds the whole system and runs its part, so it
    /// may not omit components (a spec file with [`App::new`] can). Ignored
    /// for an application made from a spec file, whose deployments it holds.
    pub fn deployment(mut self, ron: impl Into<String>) -> App {
        if let Some(code) = &mut self.code {
            code.deployments.push(ron.into());
        }
        self
    }

    /// The spec of a system built in code: exported from it once, with the
    /// deployments given.
    fn export(&mut self) -> Result<(), AppError> {
        let Some(code) = &self.code else {
            return Ok(());
        };
        if !self.text.is_empty() {
            return Ok(());
        }
        let build = self.build.as_mut().ok_or_else(|| {
            AppError::invalid("App::from_code was not given a function that builds the system")
        })?;
        let system = build(&Target::Whole).map_err(AppError::Build)?;
        let mut spec = agent_spec::export::spec_of(&code.name, system.info())
            .map_err(|e| AppError::invalid(format!("the spec of the system built in code: {e}")))?;
        for (k, text) in code.deployments.iter().enumerate() {
            // As in a spec file: optional fields without `Some(...)`.
            let deployment: agent_spec::model::Deployment =
                agent_spec::options().from_str(text).map_err(|e| {
                    AppError::invalid(format!(
                        "deployment {} given to App::deployment: {e}",
                        k + 1
                    ))
                })?;
            if !deployment.omit.is_empty() {
                return Err(AppError::invalid(format!(
                    "deployment `{}` omits {}: a system built in code runs whole in every process (give a spec file with App::new to omit components)",
                    deployment.name,
                    deployment.omit.join(", ")
                )));
            }
            spec.deployments.push(deployment);
        }
        self.text = agent_spec::export::to_ron(&spec)
            .map_err(|e| AppError::invalid(format!("the spec of the system built in code: {e}")))?;
        Ok(())
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
        self.export()?;
        Ok(vec![()])
    }

    fn reconfigure(&mut self, (): (), _: &NoFlags, _: &Common) -> Result<(), AppError> {
        self.export()
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
