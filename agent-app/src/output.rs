//! Where the layer writes: the summary on standard output, everything else
//! (progress, timing tables, warnings, errors) on standard error, each line
//! prefixed with the program's name where it is a message.

use std::io::Write;

/// The program's name as invoked (`rex`), for messages.
pub(crate) fn program() -> String {
    std::env::args()
        .next()
        .and_then(|a| {
            std::path::Path::new(&a)
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
        })
        .unwrap_or_else(|| "app".to_owned())
}

/// Write to standard output; if it is closed (`program | head`), end the
/// program quietly instead of panicking.
pub fn emit(text: std::fmt::Arguments<'_>) {
    if std::io::stdout().lock().write_fmt(text).is_err() {
        std::process::exit(0);
    }
}

pub(crate) fn out(text: std::fmt::Arguments<'_>) {
    emit(text);
}

/// A line on standard error (ignored if it is closed).
pub(crate) fn err(text: std::fmt::Arguments<'_>) {
    let _ = writeln!(std::io::stderr().lock(), "{text}");
}

/// `<program>: warning: ...` on standard error.
pub(crate) fn warn(text: std::fmt::Arguments<'_>) {
    err(format_args!("{}: warning: {text}", program()));
}

/// `<program>: ...` (an error) on standard error.
pub(crate) fn error(e: &dyn std::fmt::Display) {
    err(format_args!("{}: {e}", program()));
}
