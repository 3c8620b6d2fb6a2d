//! Loading RON configuration files, with errors that name the file and the position.

use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;

/// A configuration that could not be used.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The file is not valid RON for this type.
    #[error("{path}:{line}:{col}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// Line (1-based).
        line: usize,
        /// Column (1-based).
        col: usize,
        /// What is wrong.
        message: String,
    },
    /// A value is out of its domain (negative mass, NaN friction...).
    #[error("{path}: {field} = {value} is invalid: {reason}")]
    Invalid {
        /// The file (or `<built-in>`).
        path: PathBuf,
        /// Which field.
        field: String,
        /// Its value, as written.
        value: String,
        /// What it must be.
        reason: &'static str,
    },
    /// A value that does not fit another part of the configuration (a plan's
    /// point inside an obstacle of the world).
    #[error("{path}: {field} {reason}")]
    Mismatch {
        /// The file.
        path: PathBuf,
        /// Which field.
        field: String,
        /// Why, with the values.
        reason: String,
    },
}

/// A name on the command line or in a run file that names none of a choice's
/// options: `unknown tracker `pid` (backstepping, nmpc)`.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown {what} `{given}` ({options})")]
pub struct UnknownChoice {
    /// What was chosen (`tracker`).
    pub what: &'static str,
    /// The name given.
    pub given: String,
    /// The names it may be, comma-separated.
    pub options: &'static str,
}

impl UnknownChoice {
    /// `given` is not one of `options` for `what`.
    pub fn new(what: &'static str, given: &str, options: &'static str) -> Self {
        UnknownChoice {
            what,
            given: given.to_owned(),
            options,
        }
    }
}

/// Something that can check its own values.
pub trait Validate {
    /// `Err((field, value, reason))` for the first invalid value.
    fn validate(&self) -> Result<(), Invalid>;
}

/// An invalid value: (field, value, reason).
pub type Invalid = (String, String, &'static str);

/// Require `x > 0` and finite.
pub fn positive(field: &str, x: f64) -> Result<(), Invalid> {
    if x.is_finite() && x > 0.0 {
        Ok(())
    } else {
        Err((
            field.to_owned(),
            x.to_string(),
            "must be a positive finite number",
        ))
    }
}

/// Require `x >= 0` and finite.
pub fn non_negative(field: &str, x: f64) -> Result<(), Invalid> {
    if x.is_finite() && x >= 0.0 {
        Ok(())
    } else {
        Err((
            field.to_owned(),
            x.to_string(),
            "must be a finite number >= 0",
        ))
    }
}

/// Require a period the runtime can run ([`embodied::Period::from_millis_f64`]): a
/// positive number of milliseconds, from 1 ns to 2^64 ns.
pub fn period_ms(field: &str, ms: f64) -> Result<(), Invalid> {
    match embodied::Period::from_millis_f64(ms) {
        Ok(_) => Ok(()),
        Err(_) => Err((
            field.to_owned(),
            ms.to_string(),
            "must be a period in milliseconds: positive, at least 0.000001 (1 ns), at most 584 years",
        )),
    }
}

/// Require a finite number.
pub fn finite(field: &str, x: f64) -> Result<(), Invalid> {
    if x.is_finite() {
        Ok(())
    } else {
        Err((field.to_owned(), x.to_string(), "must be a finite number"))
    }
}

/// Parse RON text (named `path` in errors) and validate it.
pub fn parse<T: DeserializeOwned + Validate>(path: &Path, text: &str) -> Result<T, ConfigError> {
    let value: T = ron::Options::default()
        .with_default_extension(ron::extensions::Extensions::IMPLICIT_SOME)
        .from_str(text)
        .map_err(|e| ConfigError::Parse {
            path: path.to_owned(),
            line: e.span.start.line,
            col: e.span.start.col,
            message: e.code.to_string(),
        })?;
    value
        .validate()
        .map_err(|(field, value, reason)| ConfigError::Invalid {
            path: path.to_owned(),
            field,
            value,
            reason,
        })?;
    Ok(value)
}

/// Validate a value that was not read from a file (built in code, or changed by
/// command-line options): errors name `what` (in angle brackets) in place of a file.
pub fn check<T: Validate + ?Sized>(what: &str, value: &T) -> Result<(), ConfigError> {
    value
        .validate()
        .map_err(|(field, value, reason)| ConfigError::Invalid {
            path: PathBuf::from(format!("<{what}>")),
            field,
            value,
            reason,
        })
}

/// Read, parse and validate a RON file.
pub fn load<T: DeserializeOwned + Validate>(path: &Path) -> Result<T, ConfigError> {
    let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Io {
        path: path.to_owned(),
        source,
    })?;
    parse(path, &text)
}

/// The folder of Rex's shipped configuration files (`rex-agent/config`).
pub fn config_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("config")
}

/// The folder of Rex's shipped missions (`rex-agent/missions`).
pub fn missions_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("missions")
}
