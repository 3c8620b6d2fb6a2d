//! ROS 2 names as the wire needs them: the checks that keep a name a valid
//! part of a Zenoh key expression, a relative topic name made fully qualified,
//! and rmw_zenoh's mangling of names into one key chunk.
//!
//! The rules are those of `rmw`'s validation of fully qualified topic names,
//! namespaces and node names (letters, digits and `_`; tokens separated by one
//! `/`; no token starting with a digit). Length limits and the `__` rule are
//! left to the spec checker (`agent_spec::ros2`), which reports them with
//! spans and whose rules the bridge's plan applies to the names it announces.

use std::fmt;

/// What a name names, for error messages.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NameKind {
    /// A topic or service name.
    Topic,
    /// A node's namespace.
    Namespace,
    /// A node's name.
    Node,
    /// An SROS enclave.
    Enclave,
}

impl fmt::Display for NameKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Topic => "topic name",
            Self::Namespace => "namespace",
            Self::Node => "node name",
            Self::Enclave => "enclave",
        })
    }
}

/// Why a name cannot go on the wire.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum NameError {
    /// The name is empty.
    #[error("the {kind} is empty")]
    Empty {
        /// What the name names.
        kind: NameKind,
    },
    /// A name that must be absolute does not start with `/`.
    #[error("the {kind} `{name}` is not absolute: it must start with `/`")]
    NotAbsolute {
        /// What the name names.
        kind: NameKind,
        /// The name.
        name: String,
    },
    /// The name ends with `/` (only the root namespace `/` may).
    #[error("the {kind} `{name}` ends with `/`")]
    TrailingSlash {
        /// What the name names.
        kind: NameKind,
        /// The name.
        name: String,
    },
    /// Two `/` follow each other.
    #[error("the {kind} `{name}` has an empty token (`//`)")]
    EmptyToken {
        /// What the name names.
        kind: NameKind,
        /// The name.
        name: String,
    },
    /// A character other than a letter, a digit, `_` or a separating `/`.
    #[error(
        "the {kind} `{name}` has `{character}` at byte {at}: only ASCII letters, digits, `_` and `/` between tokens are allowed"
    )]
    InvalidCharacter {
        /// What the name names.
        kind: NameKind,
        /// The name.
        name: String,
        /// The character.
        character: char,
        /// Its byte offset in the name.
        at: usize,
    },
    /// A token (or a node name) starts with a digit.
    #[error("the {kind} `{name}` has a token starting with a digit")]
    TokenStartsWithDigit {
        /// What the name names.
        kind: NameKind,
        /// The name.
        name: String,
    },
    /// A `{...}` substitution, which only a ROS 2 client library expands.
    #[error("the {kind} `{name}` has a substitution (`{{...}}`), which the wire cannot expand")]
    Substitution {
        /// What the name names.
        kind: NameKind,
        /// The name.
        name: String,
    },
}

/// Checks one `/`-free token: letters, digits and `_`, not starting with a digit.
fn check_token(kind: NameKind, name: &str, token: &str, offset: usize) -> Result<(), NameError> {
    if token.is_empty() {
        return Err(NameError::EmptyToken {
            kind,
            name: name.to_owned(),
        });
    }
    if let Some((at, character)) = token
        .char_indices()
        .find(|&(_, c)| !(c.is_ascii_alphanumeric() || c == '_'))
    {
        let error = if character == '{' || character == '}' {
            NameError::Substitution {
                kind,
                name: name.to_owned(),
            }
        } else {
            NameError::InvalidCharacter {
                kind,
                name: name.to_owned(),
                character,
                at: offset + at,
            }
        };
        return Err(error);
    }
    if token.starts_with(|c: char| c.is_ascii_digit()) {
        return Err(NameError::TokenStartsWithDigit {
            kind,
            name: name.to_owned(),
        });
    }
    Ok(())
}

/// Checks an absolute name (`/a/b`); `root_allowed` admits `/` itself.
fn check_absolute(kind: NameKind, name: &str, root_allowed: bool) -> Result<(), NameError> {
    if name.is_empty() {
        return Err(NameError::Empty { kind });
    }
    let Some(rest) = name.strip_prefix('/') else {
        return Err(NameError::NotAbsolute {
            kind,
            name: name.to_owned(),
        });
    };
    if rest.is_empty() && root_allowed {
        return Ok(());
    }
    if rest.is_empty() || rest.ends_with('/') {
        return Err(NameError::TrailingSlash {
            kind,
            name: name.to_owned(),
        });
    }
    let mut offset = 1;
    for token in rest.split('/') {
        check_token(kind, name, token, offset)?;
        offset += token.len() + 1;
    }
    Ok(())
}

/// Checks a fully qualified topic or service name (`/robot1/chatter`).
pub fn validate_topic_name(name: &str) -> Result<(), NameError> {
    check_absolute(NameKind::Topic, name, false)
}

/// Checks a node namespace: `/` (the root) or an absolute name.
pub fn validate_namespace(namespace: &str) -> Result<(), NameError> {
    check_absolute(NameKind::Namespace, namespace, true)
}

/// Checks an SROS enclave: `/` (none) or an absolute name.
pub fn validate_enclave(enclave: &str) -> Result<(), NameError> {
    check_absolute(NameKind::Enclave, enclave, true)
}

/// Checks a node name: one token, without `/`.
pub fn validate_node_name(name: &str) -> Result<(), NameError> {
    if name.is_empty() {
        return Err(NameError::Empty {
            kind: NameKind::Node,
        });
    }
    check_token(NameKind::Node, name, name, 0)
}

/// `namespace` and `tail` joined by one `/` (the root namespace adds nothing).
fn join(namespace: &str, tail: &str) -> String {
    if namespace == "/" {
        format!("/{tail}")
    } else {
        format!("{namespace}/{tail}")
    }
}

/// The fully qualified form of a topic name as a node in `namespace` named
/// `node` means it: an absolute name stays, `~` stands for the node's private
/// namespace (`<namespace>/<node>`), a relative name goes under the namespace.
///
/// An empty namespace means the root one (`/`). `{...}` substitutions are
/// refused: they are a client library's business, not the wire's.
pub fn qualify_topic(name: &str, namespace: &str, node: &str) -> Result<String, NameError> {
    let namespace = if namespace.is_empty() { "/" } else { namespace };
    validate_namespace(namespace)?;
    validate_node_name(node)?;
    if name.is_empty() {
        return Err(NameError::Empty {
            kind: NameKind::Topic,
        });
    }
    let qualified = if name.starts_with('/') {
        name.to_owned()
    } else if name == "~" {
        join(namespace, node)
    } else if let Some(tail) = name.strip_prefix("~/") {
        join(&join(namespace, node), tail)
    } else {
        join(namespace, name)
    };
    validate_topic_name(&qualified)?;
    Ok(qualified)
}

/// A name as one key chunk, as rmw_zenoh mangles it: each `/` becomes `%`,
/// and an empty name becomes `%` (a key chunk cannot be empty).
pub fn mangle(name: &str) -> String {
    if name.is_empty() {
        "%".to_owned()
    } else {
        name.replace('/', "%")
    }
}

/// A mangled key chunk back to the name: each `%` becomes `/`.
pub fn demangle(chunk: &str) -> String {
    chunk.replace('%', "/")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mangling_follows_the_design_documents_tokens() {
        // The root namespace and no enclave are `%`; `/chatter` is `%chatter`.
        assert_eq!(mangle("/"), "%");
        assert_eq!(mangle(""), "%");
        assert_eq!(mangle("/chatter"), "%chatter");
        assert_eq!(mangle("/robot1/chatter"), "%robot1%chatter");
        assert_eq!(mangle("talker"), "talker");
        assert_eq!(demangle("%robot1%chatter"), "/robot1/chatter");
        assert_eq!(demangle("%"), "/");
    }

    #[test]
    fn relative_and_private_names_are_qualified_with_the_namespace() {
        assert_eq!(qualify_topic("chatter", "/", "talker").unwrap(), "/chatter");
        assert_eq!(qualify_topic("chatter", "", "talker").unwrap(), "/chatter");
        assert_eq!(
            qualify_topic("chatter", "/robot1", "talker").unwrap(),
            "/robot1/chatter"
        );
        assert_eq!(
            qualify_topic("/chatter", "/robot1", "talker").unwrap(),
            "/chatter"
        );
        assert_eq!(
            qualify_topic("~/state", "/robot1", "rex").unwrap(),
            "/robot1/rex/state"
        );
        assert_eq!(qualify_topic("~", "/", "rex").unwrap(), "/rex");
        assert_eq!(
            qualify_topic("pose/estimate", "/a", "rex").unwrap(),
            "/a/pose/estimate"
        );
    }

    #[test]
    fn names_that_cannot_be_keys_are_refused_with_what_is_wrong() {
        assert_eq!(
            validate_topic_name("chatter"),
            Err(NameError::NotAbsolute {
                kind: NameKind::Topic,
                name: "chatter".into()
            })
        );
        assert!(matches!(
            validate_topic_name("/a//b"),
            Err(NameError::EmptyToken { .. })
        ));
        assert!(matches!(
            validate_topic_name("/a/"),
            Err(NameError::TrailingSlash { .. })
        ));
        assert!(matches!(
            validate_topic_name("/"),
            Err(NameError::TrailingSlash { .. })
        ));
        assert_eq!(
            validate_topic_name("/a/b*c"),
            Err(NameError::InvalidCharacter {
                kind: NameKind::Topic,
                name: "/a/b*c".into(),
                character: '*',
                at: 4
            })
        );
        assert!(matches!(
            validate_topic_name("/a/9b"),
            Err(NameError::TokenStartsWithDigit { .. })
        ));
        assert!(matches!(
            qualify_topic("{node}/x", "/", "rex"),
            Err(NameError::Substitution { .. })
        ));
        assert!(matches!(
            qualify_topic("x", "/", "a/b"),
            Err(NameError::InvalidCharacter {
                kind: NameKind::Node,
                ..
            })
        ));
        assert_eq!(validate_namespace("/"), Ok(()));
        assert_eq!(validate_enclave("/"), Ok(()));
        assert!(validate_namespace("").is_err());
        assert!(validate_node_name("").is_err());
    }
}
