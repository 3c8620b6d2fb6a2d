//! The commands of the `embodied` binary, one module each: [`check`] runs the
//! checker over spec files, [`diagram`] draws a spec, [`new`] makes an agent crate
//! from a spec, [`merge`] merges the recordings of a distributed run, [`export`]
//! exports a recording for ROS 2 tools, [`monitor`] evaluates a spec's
//! contracts over a recording.
//! `src/main.rs` parses the command line (clap) and calls them.

/// `print!` that ends quietly on a closed standard output (`embodied check |
/// head`) instead of panicking as `print!` does.
macro_rules! out {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = write!(std::io::stdout().lock(), $($arg)*);
    }};
}

/// `println!`, as [`out!`].
macro_rules! outln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout().lock(), $($arg)*);
    }};
}

/// `eprint!`, as [`out!`], on standard error.
macro_rules! err {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = write!(std::io::stderr().lock(), $($arg)*);
    }};
}

/// `eprintln!`, as [`out!`], on standard error.
macro_rules! errln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr().lock(), $($arg)*);
    }};
}

pub(crate) mod check;
pub(crate) mod diagram;
pub(crate) mod export;
pub(crate) mod merge;
pub(crate) mod monitor;
pub(crate) mod new;

/// The width at which reports are drawn: `$COLUMNS`, or 100.
pub(crate) fn width() -> usize {
    std::env::var("COLUMNS")
        .ok()
        .and_then(|c| c.parse().ok())
        .unwrap_or(100)
}
