//! The pieces of generated text laid out as rustfmt would write them, and the
//! spec's docs as doc comments.

/// The spec's doc text as doc comment lines (`prefix` is `///` or `//!`).
pub(super) fn doc(indent: &str, prefix: &str, text: Option<&String>) -> String {
    let mut out = String::new();
    for line in text.map(|t| t.lines()).into_iter().flatten() {
        let line = line.trim_end();
        if line.is_empty() {
            out += &format!("{indent}{prefix}\n");
        } else {
            out += &format!("{indent}{prefix} {line}\n");
        }
    }
    out
}

/// `/// text` lines, then an empty `///` line if there were any: the spec's doc
/// above what the crate says of an item.
pub(super) fn doc_then(indent: &str, text: Option<&String>) -> String {
    let mut out = doc(indent, "///", text);
    if !out.is_empty() {
        out += &format!("{indent}///\n");
    }
    out
}

/// An empty `//!` line, then the spec's doc as `//!` lines, if it has one.
pub(super) fn inner_doc(text: Option<&String>) -> String {
    let lines = doc("", "//!", text);
    if lines.is_empty() {
        lines
    } else {
        format!("//!\n{lines}")
    }
}

/// The parameters of a function as rustfmt writes them: on the signature's line
/// if it fits in 100 columns, else one per line.
pub(super) fn params(head: &str, params: &[String], tail: &str) -> String {
    let line = params.join(", ");
    if head.len() + line.len() + tail.len() <= 100 {
        line
    } else {
        let mut out = String::from("\n");
        for p in params {
            out += &format!("        {p},\n");
        }
        out + "    "
    }
}

/// `Ok(assembly.<method>(<args>)?)` in a function's body, as rustfmt writes it:
/// on one line if it fits in 100 columns, else one argument per line.
pub(super) fn call(method: &str, args: &[String]) -> String {
    let line = format!("    Ok(assembly.{method}({})?)", args.join(", "));
    if line.len() <= 100 {
        return line;
    }
    let mut out = format!("    Ok(assembly.{method}(\n");
    for a in args {
        out += &format!("        {a},\n");
    }
    out + "    )?)"
}

/// A shell command of a doc comment and what it does, its `#` in the column of
/// the others (or one space after a longer command).
pub(super) fn aligned(command: &str, comment: &str) -> String {
    format!("{command:<42} # {comment}")
}

/// A TOML basic string.
pub(super) fn toml_string(text: &str) -> String {
    let mut out = String::from("\"");
    for c in text.chars() {
        match c {
            '"' => out += "\\\"",
            '\\' => out += "\\\\",
            c if c.is_control() => out += &format!("\\u{:04X}", u32::from(c)),
            c => out.push(c),
        }
    }
    out + "\""
}

/// `#[allow(non_snake_case)]` (with its reason) before an item named by a component
/// with capitals.
pub(super) fn allow_case<'a>(names: impl IntoIterator<Item = &'a str>) -> &'static str {
    if names
        .into_iter()
        .any(|n| n.chars().any(|c| c.is_ascii_uppercase()))
    {
        "#[allow(non_snake_case, reason = \"the spec's component names (E1)\")]\n"
    } else {
        ""
    }
}
