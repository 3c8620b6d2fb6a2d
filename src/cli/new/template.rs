//! The templates of `embodied new`: the files under `templates/new/`, built into
//! the binary, with `{{slot}}`s that [`Template::fill`] replaces.
//!
//! A template under `templates/new/` at the path of a file of the new crate
//! (`src/system.rs.tmpl`) is that file; one under `templates/new/parts/` is a piece
//! repeated or chosen by the spec (a driver, a stub, a termination test). A slot is
//! `{{` an identifier `}}`; any other `{{` is text.

use std::fmt;

/// A template: its path under `templates/new/` and its text.
#[derive(Clone, Copy, Debug)]
pub(super) struct Template {
    path: &'static str,
    text: &'static str,
}

/// The template at `$path` under `templates/new/`, read at compile time.
macro_rules! template {
    ($path:literal) => {
        Template {
            path: $path,
            text: include_str!(concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/templates/new/",
                $path
            )),
        }
    };
}

// The new crate's files.
pub(super) const CARGO_TOML: Template = template!("Cargo.toml.tmpl");
pub(super) const CARGO_CONFIG: Template = template!("cargo-config.toml.tmpl");
pub(super) const GITIGNORE: Template = template!("gitignore.tmpl");
pub(super) const README: Template = template!("README.md.tmpl");
pub(super) const LIB: Template = template!("src/lib.rs.tmpl");
pub(super) const MAIN: Template = template!("src/main.rs.tmpl");
pub(super) const TYPES: Template = template!("src/types.rs.tmpl");
pub(super) const LOGIC: Template = template!("src/logic.rs.tmpl");
pub(super) const LOGIC_SUBSYSTEM: Template = template!("src/logic/subsystem.rs.tmpl");
pub(super) const DEVICES: Template = template!("src/devices.rs.tmpl");
pub(super) const SYSTEM: Template = template!("src/system.rs.tmpl");
pub(super) const TESTS: Template = template!("tests/properties/main.rs.tmpl");
pub(super) const TESTS_SUBSYSTEM: Template = template!("tests/properties/subsystem.rs.tmpl");
pub(super) const TESTS_APP: Template = template!("tests/app.rs.tmpl");

/// Pieces of files, repeated or chosen by the spec.
pub(super) mod parts {
    use super::Template;

    pub(in super::super) const LIB_AGENT: Template = template!("parts/lib-agent.rs.tmpl");
    pub(in super::super) const TYPE: Template = template!("parts/type.rs.tmpl");
    pub(in super::super) const MEMORY_FN: Template = template!("parts/memory-fn.rs.tmpl");
    pub(in super::super) const OUTPUT_FN: Template = template!("parts/output-fn.rs.tmpl");
    pub(in super::super) const PREDICATE: Template = template!("parts/predicate.rs.tmpl");
    pub(in super::super) const DRIVER: Template = template!("parts/driver.rs.tmpl");
    pub(in super::super) const HANDLE_SUBSYSTEM: Template =
        template!("parts/handle-subsystem.rs.tmpl");
    pub(in super::super) const HANDLE_DRIVER: Template = template!("parts/handle-driver.rs.tmpl");
    pub(in super::super) const ADD_SUBSYSTEM: Template = template!("parts/add-subsystem.rs.tmpl");
    pub(in super::super) const ADD_DRIVER: Template = template!("parts/add-driver.rs.tmpl");
    pub(in super::super) const DEPLOYED: Template = template!("parts/deployed.rs.tmpl");
    pub(in super::super) const ENDS: Template = template!("parts/ends.rs.tmpl");
    pub(in super::super) const TEST_APP_KILL: Template = template!("parts/test-app-kill.rs.tmpl");
    pub(in super::super) const TEST_APP_LAUNCH: Template =
        template!("parts/test-app-launch.rs.tmpl");
    pub(in super::super) const README_LOGIC_ROW: Template =
        template!("parts/readme-logic-row.md.tmpl");
    pub(in super::super) const README_TEST_ROW: Template =
        template!("parts/readme-test-row.md.tmpl");
    pub(in super::super) const TEST_STAMP: Template = template!("parts/test-stamp.rs.tmpl");
    pub(in super::super) const TEST_VERDICT: Template = template!("parts/test-verdict.rs.tmpl");
    pub(in super::super) const TEST_GUIDE: Template = template!("parts/test-guide.rs.tmpl");
    pub(in super::super) const TEST_INPUT: Template = template!("parts/test-input.rs.tmpl");
    pub(in super::super) const TEST_INPUT_NONE: Template =
        template!("parts/test-input-none.rs.tmpl");
    pub(in super::super) const TEST_DELIVER: Template = template!("parts/test-deliver.rs.tmpl");
    pub(in super::super) const TEST_WORLD: Template = template!("parts/test-world.rs.tmpl");
    pub(in super::super) const TEST_WORLD_NONE: Template =
        template!("parts/test-world-none.rs.tmpl");
    pub(in super::super) const TEST_WORLD_DELIVER: Template =
        template!("parts/test-world-deliver.rs.tmpl");
    pub(in super::super) const TEST_WORLD_AGE: Template = template!("parts/test-world-age.rs.tmpl");
    pub(in super::super) const TEST_TERMINATION: Template =
        template!("parts/test-termination.rs.tmpl");
}

/// A template could not be filled: a slot without a value, or a value without a
/// slot. The templates and the code that fills them disagree (a bug of the CLI).
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct TemplateError {
    template: &'static str,
    problem: String,
}

impl fmt::Display for TemplateError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "template `templates/new/{}`: {} (a bug of `embodied new`)",
            self.template, self.problem
        )
    }
}

impl std::error::Error for TemplateError {}

impl Template {
    /// The text with each slot replaced by its value in `values`. Every slot must
    /// have a value, and every value a slot.
    pub(super) fn fill(&self, values: &[(&str, &str)]) -> Result<String, TemplateError> {
        let error = |problem: String| TemplateError {
            template: self.path,
            problem,
        };
        let mut out = String::with_capacity(self.text.len());
        let mut used = vec![false; values.len()];
        let mut rest = self.text;
        while let Some(at) = rest.find("{{") {
            out.push_str(&rest[..at]);
            let after = &rest[at + 2..];
            let len = after
                .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                .unwrap_or(after.len());
            if len == 0 || !after[len..].starts_with("}}") {
                out.push_str("{{");
                rest = after;
                continue;
            }
            let key = &after[..len];
            let Some(k) = values.iter().position(|(name, _)| *name == key) else {
                return Err(error(format!("no value for the slot `{{{{{key}}}}}`")));
            };
            out.push_str(values[k].1);
            used[k] = true;
            rest = &after[len + 2..];
        }
        out.push_str(rest);
        match used.iter().position(|u| !u) {
            Some(k) => Err(error(format!("no slot `{{{{{}}}}}`", values[k].0))),
            None => Ok(out),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slots_are_identifiers_between_double_braces() {
        let t = Template {
            path: "t",
            text: "a {{x}} b {{ y }} {{x}}{{z_1}} {{}} {{",
        };
        assert_eq!(
            t.fill(&[("x", "1"), ("z_1", "2")]).unwrap(),
            "a 1 b {{ y }} 12 {{}} {{"
        );
        assert_eq!(
            t.fill(&[("x", "1")]).unwrap_err().to_string(),
            "template `templates/new/t`: no value for the slot `{{z_1}}` (a bug of `embodied new`)"
        );
        assert_eq!(
            t.fill(&[("x", "1"), ("z_1", "2"), ("w", "3")])
                .unwrap_err()
                .problem,
            "no slot `{{w}}`"
        );
    }
}
