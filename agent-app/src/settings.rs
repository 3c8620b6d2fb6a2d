//! A program's run file: the settings of a run in a file named on the
//! command line (`--config FILE`) or shipped with the program, whose relative
//! paths are taken from the file's folder. A run's settings are made
//! self-contained (every path absolute, [`absolute`]) before they are
//! recorded, so that a replay builds the same system from any folder.
//!
//! ```
//! use std::path::{Path, PathBuf};
//! use agent_app::settings::{absolute, run_file};
//!
//! # fn main() -> Result<(), agent_app::AppError> {
//! let shipped = Path::new("/opt/robot/config/robot.ron");
//! let read = |path: &Path| Ok::<_, String>(format!("settings of {}", path.display()));
//! let (settings, base) = run_file(None, shipped, read)?;
//! assert_eq!(settings, "settings of /opt/robot/config/robot.ron");
//! assert_eq!(base, Path::new("/opt/robot/config"));
//! assert_eq!(absolute(&base, Path::new("world.ron")), Path::new("/opt/robot/config/world.ron"));
//! # Ok(())
//! # }
//! ```

use std::fmt::Display;
use std::path::{Path, PathBuf};

use crate::AppError;

/// The settings of the run file `given` (named on the command line) or, if
/// none is, of the program's `shipped` one, read by `load`, with the folder
/// their relative paths are taken from (the file's). A file that `load`
/// refuses is invalid input ([`AppError::Invalid`], with `load`'s words,
/// which name the file and the field).
pub fn run_file<T, E: Display>(
    given: Option<&Path>,
    shipped: &Path,
    load: impl FnOnce(&Path) -> Result<T, E>,
) -> Result<(T, PathBuf), AppError> {
    let path = given.unwrap_or(shipped);
    let settings = load(path).map_err(AppError::invalid)?;
    let base = path.parent().map_or_else(PathBuf::new, Path::to_path_buf);
    Ok((settings, base))
}

/// `path` taken from `base` (the folder of the file that named it; the
/// current folder when `base` is empty) and made absolute as
/// [`std::path::absolute`] does (its `..` kept; as it is if the current
/// folder cannot be read).
pub fn absolute(base: &Path, path: &Path) -> PathBuf {
    let joined = base.join(path);
    std::path::absolute(&joined).unwrap_or(joined)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_given_file_is_read_rather_than_the_shipped_one() {
        let read = |path: &Path| -> Result<PathBuf, String> {
            match path.to_str() {
                Some("bad.ron") => Err("bad.ron: field `limit_s`: not a number".into()),
                _ => Ok(path.to_owned()),
            }
        };
        let shipped = Path::new("/ship/config/run.ron");
        let (read_from, base) = run_file(Some(Path::new("runs/a.ron")), shipped, read)
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            (read_from.as_path(), base.as_path()),
            (Path::new("runs/a.ron"), Path::new("runs"))
        );
        let (_, base) =
            run_file(Some(Path::new("a.ron")), shipped, read).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(base, Path::new(""), "a file in the current folder");
        let err = run_file(Some(Path::new("bad.ron")), shipped, read).err();
        let err = err.unwrap_or_else(|| panic!("bad.ron is refused"));
        assert_eq!(err.status(), crate::Status::Invalid);
        assert!(err.to_string().contains("field `limit_s`"), "{err}");
    }

    #[test]
    fn paths_are_made_absolute_from_their_base() {
        let cwd = std::env::current_dir().unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            absolute(Path::new(""), Path::new("w.ron")),
            cwd.join("w.ron")
        );
        assert_eq!(
            absolute(Path::new("/a/b"), Path::new("./c/d.ron")),
            Path::new("/a/b/c/d.ron")
        );
        assert_eq!(
            absolute(Path::new("/a/b"), Path::new("/etc/x")),
            Path::new("/etc/x")
        );
    }
}
