//! The message types of an export: every `ros2msg` schema kept parsed into
//! its definitions, and each name given to one definition only.
//!
//! ROS 2 has one definition per type name (`pkg/msg/Name`), and a ROS 2
//! reader registers the definitions of every schema of a file into one type
//! store (rosbags' `AnyReader` does), so two schemas that define one name
//! differently make it decode a channel with the other's definition (rosbags:
//! "buffer is smaller than requested size"). The recorder names the helper
//! messages of each payload type on their own: `embodied/Item`, the element
//! of an array of arrays, is `float64[4] value` in Rex's 4x4 transforms and
//! `float64[5] value` elsewhere. So the export renames: a definition whose
//! name another definition already has gets it with the first free number
//! (`Item2`), and the fields that use it are rewritten. Names are also made
//! what ROS 2 allows (package `^[a-z][a-z0-9_]*$` without `__`, message
//! `^[A-Z][A-Za-z0-9]*$`), and schema names are `pkg/msg/Name`.

use std::collections::{BTreeMap, HashMap, HashSet};

/// A message type's package and name (`embodied`, `State`).
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
struct TypeName {
    package: String,
    name: String,
}

impl TypeName {
    /// `pkg/msg/Name` or `pkg/Name`; a bare `Name` is in `owner`'s package.
    fn parse(text: &str, owner: Option<&str>) -> Option<TypeName> {
        let parts: Vec<&str> = text.split('/').collect();
        let (package, name) = match parts.as_slice() {
            [name] => (owner?, *name),
            [package, name] | [package, "msg", name] => (*package, *name),
            _ => return None,
        };
        (!package.is_empty() && !name.is_empty()).then(|| TypeName {
            package: package.to_owned(),
            name: name.to_owned(),
        })
    }

    /// `pkg/msg/Name`: a schema's name in MCAP's `ros2` profile.
    fn full(&self) -> String {
        format!("{}/msg/{}", self.package, self.name)
    }

    /// `pkg/Name`: how a field's type and a `MSG:` line name it.
    fn short(&self) -> String {
        format!("{}/{}", self.package, self.name)
    }

    /// The name ROS 2 allows nearest to this one: the package in lower case,
    /// other characters `_` (once, none at its ends); the message's name of
    /// ASCII letters and digits only, starting with an upper-case letter.
    fn valid(&self) -> TypeName {
        let mut package = String::new();
        for c in self.package.chars().map(|c| c.to_ascii_lowercase()) {
            let c = if c.is_ascii_lowercase() || c.is_ascii_digit() {
                c
            } else {
                '_'
            };
            if !(c == '_' && (package.is_empty() || package.ends_with('_'))) {
                package.push(c);
            }
        }
        let mut package = package.trim_end_matches('_').to_owned();
        if !package.starts_with(|c: char| c.is_ascii_lowercase()) {
            package.insert(0, 'p');
        }
        let mut name: String = self
            .name
            .chars()
            .filter(char::is_ascii_alphanumeric)
            .collect();
        if let Some(first) = name.chars().next().filter(char::is_ascii_lowercase) {
            name.replace_range(..1, &first.to_ascii_uppercase().to_string());
        }
        if !name.starts_with(|c: char| c.is_ascii_uppercase()) {
            name.insert(0, 'M');
        }
        TypeName { package, name }
    }
}

/// A line of a definition: a field of a message type, or anything else
/// (a primitive field, a constant, a comment), kept as written.
#[derive(Clone, Debug)]
enum Line {
    Text(String),
    Field {
        /// The message type.
        ty: TypeName,
        /// What follows its name in the type (`[4]`, `[<=1]`, `[]`).
        suffix: String,
        /// The rest of the line (the field's name, a default).
        tail: String,
    },
}

/// One definition of a schema: the root's, or one behind a `MSG:` line.
#[derive(Clone, Debug)]
struct Section {
    name: TypeName,
    lines: Vec<Line>,
}

/// Whether `line` separates definitions (a line of `=`).
fn is_separator(line: &str) -> bool {
    let line = line.trim();
    line.len() >= 3 && line.chars().all(|c| c == '=')
}

/// A line of a definition in `package`.
fn parse_line(line: &str, package: &str) -> Line {
    let body = line.trim_start();
    let end = body.find(char::is_whitespace).unwrap_or(body.len());
    let token = &body[..end];
    let base_end = token.find('[').unwrap_or(token.len());
    let base = &token[..base_end];
    // A message's name starts with an upper-case letter; primitives and
    // bounded strings do not, nor does a comment.
    let last = base.rsplit('/').next().unwrap_or_default();
    if !last.starts_with(|c: char| c.is_ascii_uppercase()) {
        return Line::Text(line.to_owned());
    }
    match TypeName::parse(base, Some(package)) {
        Some(ty) => Line::Field {
            ty,
            suffix: token[base_end..].to_owned(),
            tail: body[end..].to_owned(),
        },
        None => Line::Text(line.to_owned()),
    }
}

/// The definitions of the schema `name` whose text is `text`: the root's
/// first, then each behind its separator and `MSG: pkg/Name` line.
fn parse_schema(name: &str, text: &str) -> Result<Vec<Section>, String> {
    let root = TypeName::parse(name, None)
        .ok_or_else(|| format!("its schema's name `{name}` is not `package/msg/Name`"))?;
    let mut sections = vec![Section {
        name: root,
        lines: Vec::new(),
    }];
    let mut lines = text.lines();
    while let Some(line) = lines.next() {
        let package = sections
            .last()
            .map(|s| s.name.package.clone())
            .unwrap_or_default();
        if is_separator(line) {
            let header = lines.next().unwrap_or_default().trim();
            let named = header
                .strip_prefix("MSG:")
                .and_then(|n| TypeName::parse(n.trim(), Some(&package)))
                .ok_or_else(|| {
                    format!("a separator followed by `{header}`, not `MSG: package/Name`")
                })?;
            if sections.iter().any(|s| s.name == named) {
                return Err(format!("its schema defines `{}` twice", named.short()));
            }
            sections.push(Section {
                name: named,
                lines: Vec::new(),
            });
        } else if let Some(last) = sections.last_mut() {
            last.lines.push(parse_line(line, &package));
        }
    }
    Ok(sections)
}

/// The words of `text`, one space between each: a line as compared.
fn words(text: &str) -> String {
    text.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// The schemas taken so far, each definition interned: two definitions are
/// one when their names, their lines and the definitions their fields use
/// are.
#[derive(Default)]
pub(crate) struct Types {
    /// Each distinct definition's id, by its name and lines (fields naming
    /// the ids of their types).
    ids: HashMap<(TypeName, String), usize>,
    /// Each definition's name in the recording, by id.
    names: Vec<TypeName>,
    /// The schemas taken, by their id in the recording: their definitions
    /// and each one's id.
    schemas: BTreeMap<u16, (Vec<Section>, Vec<usize>)>,
}

impl Types {
    /// Take the `ros2msg` schema `id` of the recording: its name and text.
    /// Refused, with the reason: a schema that does not parse, uses a type
    /// it does not define, or a type that contains itself.
    pub(crate) fn take(&mut self, id: u16, name: &str, text: &str) -> Result<(), String> {
        if self.schemas.contains_key(&id) {
            return Ok(());
        }
        let sections = parse_schema(name, text)?;
        let mut ids = vec![None; sections.len()];
        for k in 0..sections.len() {
            self.intern(&sections, k, &mut ids, 0)?;
        }
        // `intern` gave every definition its id or returned an error.
        let ids = ids
            .into_iter()
            .collect::<Option<Vec<usize>>>()
            .ok_or_else(|| format!("`{name}`: a definition was left without an id"))?;
        self.schemas.insert(id, (sections, ids));
        Ok(())
    }

    /// The id of definition `k` of `sections` (and of every definition it
    /// uses), interned.
    fn intern(
        &mut self,
        sections: &[Section],
        k: usize,
        ids: &mut [Option<usize>],
        depth: usize,
    ) -> Result<usize, String> {
        if let Some(id) = ids[k] {
            return Ok(id);
        }
        let section = &sections[k];
        if depth > sections.len() {
            return Err(format!("`{}` contains itself", section.name.short()));
        }
        // Bounded recursion: a crafted schema of thousands of chained
        // definitions is refused, not a stack overflow.
        if depth > crate::postcard::MAX_DEPTH {
            return Err(format!(
                "`{}` nests messages more than {} deep",
                section.name.short(),
                crate::postcard::MAX_DEPTH
            ));
        }
        let mut key = String::new();
        for line in &section.lines {
            match line {
                Line::Text(t) if t.trim().is_empty() || t.trim().starts_with('#') => continue,
                Line::Text(t) => key.push_str(&words(t)),
                Line::Field { ty, suffix, tail } => {
                    let j = sections.iter().position(|s| s.name == *ty).ok_or_else(|| {
                        format!(
                            "`{}` uses `{}`, which its schema does not define",
                            section.name.short(),
                            ty.short()
                        )
                    })?;
                    let id = self.intern(sections, j, ids, depth + 1)?;
                    key.push_str(&format!("#{id}{suffix} {}", words(tail)));
                }
            }
            key.push('\n');
        }
        let next = self.names.len();
        let id = *self.ids.entry((section.name.clone(), key)).or_insert(next);
        if id == next {
            self.names.push(section.name.clone());
        }
        ids[k] = Some(id);
        Ok(id)
    }

    /// Every definition named: the first of a name keeps it (made valid),
    /// the others get it with the first free number (`Item2`).
    pub(crate) fn named(self) -> Named {
        let wanted: Vec<TypeName> = self.names.iter().map(TypeName::valid).collect();
        let reserved: HashSet<&TypeName> = wanted.iter().collect();
        let mut taken = HashSet::new();
        let mut names = Vec::with_capacity(wanted.len());
        let mut renamed = Vec::new();
        for (id, want) in wanted.iter().enumerate() {
            let mut name = want.clone();
            let mut k = 1;
            while taken.contains(&name) || (k > 1 && reserved.contains(&name)) {
                k += 1;
                name = TypeName {
                    package: want.package.clone(),
                    name: format!("{}{k}", want.name),
                };
            }
            if name != self.names[id] {
                renamed.push((self.names[id].full(), name.full()));
            }
            taken.insert(name.clone());
            names.push(name);
        }
        Named {
            names,
            schemas: self.schemas,
            renamed,
        }
    }
}

/// The schemas with every definition named once.
pub(crate) struct Named {
    /// Each definition's name in the export, by id.
    names: Vec<TypeName>,
    schemas: BTreeMap<u16, (Vec<Section>, Vec<usize>)>,
    /// The definitions renamed: (in the recording, in the export), each
    /// `pkg/msg/Name`.
    pub(crate) renamed: Vec<(String, String)>,
}

impl Named {
    /// The schema `id` of the recording as the export writes it: its name
    /// (`pkg/msg/Name`) and its `ros2msg` text, every type renamed.
    pub(crate) fn schema(&self, id: u16) -> Option<(String, String)> {
        let (sections, ids) = self.schemas.get(&id)?;
        let named = |ty: &TypeName| {
            let k = sections.iter().position(|s| s.name == *ty)?;
            Some(self.names[ids[k]].short())
        };
        let mut text = String::new();
        for (k, section) in sections.iter().enumerate() {
            if k > 0 {
                text.push_str(&"=".repeat(80));
                text.push_str(&format!("\nMSG: {}\n", self.names[ids[k]].short()));
            }
            for line in &section.lines {
                match line {
                    Line::Text(t) => text.push_str(t),
                    Line::Field { ty, suffix, tail } => {
                        text.push_str(&format!("{}{suffix}{tail}", named(ty)?));
                    }
                }
                text.push('\n');
            }
        }
        Some((self.names[*ids.first()?].full(), text))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MATRIX: &str = "embodied/Item[4] matrix\nfloat64 from\n\
        ================================================================================\n\
        MSG: embodied/Item\nfloat64[4] value\n";
    const ROWS: &str = "Item[2] rows\nuint32 FIRST=0\n\
        ================================================================================\n\
        MSG: embodied/Item\nfloat64[5] value\n";

    #[test]
    fn two_definitions_of_one_name_get_two_names_and_their_users_follow() {
        let mut types = Types::default();
        types.take(1, "embodied/msg/Transform", MATRIX).unwrap();
        types.take(2, "embodied/Rows", ROWS).unwrap();
        // The same definition again, with other spacing: one definition.
        let again = MATRIX.replace("float64 from", "float64   from  ");
        types.take(3, "embodied/msg/Transform", &again).unwrap();
        let named = types.named();
        assert_eq!(
            named.renamed,
            [(
                "embodied/msg/Item".to_owned(),
                "embodied/msg/Item2".to_owned()
            )]
        );
        let (name, text) = named.schema(1).unwrap();
        assert_eq!(name, "embodied/msg/Transform");
        assert_eq!(text, MATRIX);
        let (name, text) = named.schema(2).unwrap();
        assert_eq!(name, "embodied/msg/Rows");
        assert_eq!(
            text,
            ROWS.replace("Item[2]", "embodied/Item2[2]")
                .replace("MSG: embodied/Item\n", "MSG: embodied/Item2\n")
        );
        assert_eq!(named.schema(3).unwrap().0, "embodied/msg/Transform");
    }

    #[test]
    fn a_root_named_like_another_definition_is_renamed_and_a_free_number_is_taken() {
        let mut types = Types::default();
        types.take(1, "a/msg/Item", "float64 x\n").unwrap();
        types.take(2, "a/msg/Item2", "float64 y\n").unwrap();
        types.take(3, "a/msg/Item", "float64 z\n").unwrap();
        let named = types.named();
        assert_eq!(named.schema(3).unwrap().0, "a/msg/Item3");
        assert_eq!(named.schema(2).unwrap().0, "a/msg/Item2");
    }

    #[test]
    fn names_ros_2_refuses_are_made_valid() {
        let mut types = Types::default();
        types
            .take(
                1,
                "My-Pkg/msg/odd_name",
                "x__y/Inner_1 inner\n===\nMSG: x__y/Inner_1\nbool b\n",
            )
            .unwrap();
        let named = types.named();
        let (name, text) = named.schema(1).unwrap();
        assert_eq!(name, "my_pkg/msg/Oddname");
        assert!(text.starts_with("x_y/Inner1 inner\n"), "{text}");
        assert!(text.contains("MSG: x_y/Inner1\nbool b\n"), "{text}");
        assert_eq!(named.renamed.len(), 2);
    }

    #[test]
    fn schemas_that_do_not_hold_together_are_refused_with_the_reason() {
        let mut types = Types::default();
        let e = types.take(1, "State", "float64 x\n").unwrap_err();
        assert!(e.contains("not `package/msg/Name`"), "{e}");
        let e = types.take(2, "a/msg/A", "a/B b\n").unwrap_err();
        assert!(e.contains("`a/B`, which its schema does not define"), "{e}");
        let e = types
            .take(
                3,
                "a/msg/A",
                "B b\n====\nMSG: a/B\nA a\n====\nMSG: a/A\nB b\n",
            )
            .unwrap_err();
        assert!(e.contains("twice") || e.contains("itself"), "{e}");
        let e = types
            .take(
                4,
                "a/msg/A",
                "B b\n====\nMSG: a/B\nC c\n====\nMSG: a/C\nB b\n",
            )
            .unwrap_err();
        assert!(e.contains("contains itself"), "{e}");
        let e = types
            .take(5, "a/msg/A", "B b\n====\nfloat64 x\n")
            .unwrap_err();
        assert!(e.contains("not `MSG: package/Name`"), "{e}");
    }

    #[test]
    fn a_chain_of_definitions_deeper_than_the_bound_is_refused_not_a_stack_overflow() {
        // a/A uses a/T1, which uses a/T2, ... 1,000 deep (tens of thousands,
        // without the bound, would take the thread's stack).
        let n = 1_000;
        let mut text = String::from("T1 t\n");
        for k in 1..n {
            text.push_str(&format!("====\nMSG: a/T{k}\nT{} t\n", k + 1));
        }
        text.push_str(&format!("====\nMSG: a/T{n}\nfloat64 x\n"));
        let e = Types::default().take(1, "a/msg/A", &text).unwrap_err();
        assert!(e.contains("nests messages more than 128 deep"), "{e}");
    }

    #[test]
    fn primitives_constants_and_comments_stay_as_written() {
        let text = "# a comment\nstring<=8 name\nuint8 IDLE=0\nbuiltin_interfaces/Time[<=1] stamp # when\n\
            ================================================================================\n\
            MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n";
        let mut types = Types::default();
        types.take(1, "embodied/msg/Stamped", text).unwrap();
        let named = types.named();
        assert!(named.renamed.is_empty());
        assert_eq!(named.schema(1).unwrap().1, text);
    }
}
