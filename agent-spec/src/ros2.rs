//! ROS 2's rules for names, and the ROS 2 interface a spec describes.
//!
//! The name rules are those of ROS 2's design article "Topic and Service name
//! mapping to DDS" (design.ros2.org/articles/topic_and_service_names.html), of
//! `rcl`'s and `rmw`'s validators (lengths, namespaces, node names), of REP 144
//! (package names) and of `rosidl` (message type names). The checker applies
//! them to a spec's `ros2` sections. The ROS 2 bridge's plan
//! (`agent_ros2::bridge::Plan::new`) applies the same functions to the node,
//! namespace and package of the section it is given and to each topic's
//! fully qualified name ([`check_node`], [`check_namespace`],
//! [`check_package`], [`check_full_topic`]), so a plan made from an unchecked
//! spec announces no name the checker refuses. (The bridge's wire layer
//! checks only what a Zenoh key needs, and is laxer.)
//!
//! Where the design article is stricter than `rcl`'s validator, these rules
//! follow the article: a topic token has single underscores only (no `__`), and
//! no token ends with `_` before a `/` (the article's `foo_/bar`). A name
//! accepted here is accepted by every ROS 2 tool. Two features of ROS 2 names
//! are handled as follows: the private namespace `~` (`~` or `~/name`: the
//! node's namespace and name) is expanded, since a spec fixes both; a
//! substitution `{...}` is refused, since its keys are not fixed by ROS 2 and a
//! spec can write the name it would stand for. URL forms (`rostopic://`) are
//! refused too.
//!
//! [`interface`] gives what a system or one of its deployments shows to ROS 2,
//! every default applied: the node, its namespace and domain, each topic's
//! fully qualified name, message and quality of service.

use std::fmt;
use std::ops::Range;

use crate::model::{Deployment, Durability, Policy, Qos, Reliability, Ros2, Ros2Topic, Spec};

/// The largest `ROS_DOMAIN_ID` ROS 2 accepts.
pub const DOMAIN_MAX: u32 = 232;

/// The longest node name, in bytes (`RMW_NODE_NAME_MAX_NAME_LENGTH`).
pub const NODE_NAME_MAX: usize = 255;

/// The longest fully qualified topic name, in bytes (`RMW_TOPIC_MAX_NAME_LENGTH`:
/// 255 less 8 reserved for the middleware's prefixes).
pub const TOPIC_NAME_MAX: usize = 247;

/// The longest namespace, in bytes (`RMW_NAMESPACE_MAX_LENGTH`: room is left for
/// the shortest topic in it, `/x`).
pub const NAMESPACE_MAX: usize = TOPIC_NAME_MAX - 2;

/// A rule of ROS 2's names that a name breaks.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Rule {
    /// The name is empty.
    Empty,
    /// A character the name may not have.
    Character(char),
    /// An uppercase letter in a package name.
    Uppercase(char),
    /// The name, or one of its tokens, starts with a digit.
    StartsWithDigit,
    /// A package name that starts with `_`.
    StartsWithUnderscore,
    /// Two `/` in a row: an empty token.
    EmptyToken,
    /// The name ends with `/`.
    TrailingSlash,
    /// `__` in the name.
    DoubleUnderscore,
    /// A token that ends with `_` before a `/`.
    UnderscoreBeforeSlash,
    /// A package name that ends with `_`.
    TrailingUnderscore,
    /// `~` anywhere but as the first token.
    Tilde,
    /// A substitution `{...}`.
    Substitution,
    /// A name that must be absolute and does not start with `/`.
    NotAbsolute,
    /// Longer than ROS 2 allows.
    TooLong {
        /// Its length in bytes.
        len: usize,
        /// The most allowed.
        max: usize,
    },
    /// A package name of one character.
    TooShort,
    /// A message type that is not `package/msg/Type`.
    MessageForm,
    /// A message type whose middle part is not `msg`.
    NotMsg,
    /// A message type whose type name does not start with an uppercase letter.
    TypeStart(char),
}

impl fmt::Display for Rule {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Rule::Empty => f.write_str("it is empty"),
            Rule::Character(c) => write!(f, "`{}` is not allowed in it", c.escape_debug()),
            Rule::Uppercase(c) => write!(f, "`{c}` is uppercase (package names are lowercase)"),
            Rule::StartsWithDigit => f.write_str("it, or one of its tokens, starts with a digit"),
            Rule::StartsWithUnderscore => {
                f.write_str("it starts with `_` (package names start with a letter)")
            }
            Rule::EmptyToken => f.write_str("it has an empty token (`//`)"),
            Rule::TrailingSlash => f.write_str("it ends with `/`"),
            Rule::DoubleUnderscore => f.write_str("it has `__` (ROS 2 names take single `_`)"),
            Rule::UnderscoreBeforeSlash => {
                f.write_str("a token ends with `_` before a `/` (as in `foo_/bar`)")
            }
            Rule::TrailingUnderscore => f.write_str("it ends with `_`"),
            Rule::Tilde => f.write_str("`~` is allowed only as its first token (`~` or `~/name`)"),
            Rule::Substitution => f.write_str("it has a substitution `{...}`"),
            Rule::NotAbsolute => f.write_str("it does not start with `/`"),
            Rule::TooLong { len, max } => {
                write!(f, "it is {len} bytes long, more than ROS 2's {max}")
            }
            Rule::TooShort => f.write_str("it has fewer than 2 characters"),
            Rule::MessageForm => f.write_str("it is not `package/msg/Type`"),
            Rule::NotMsg => f.write_str("its middle part is not `msg` (topics carry messages)"),
            Rule::TypeStart(c) => write!(
                f,
                "its type name starts with `{}`, not an uppercase letter",
                c.escape_debug()
            ),
        }
    }
}

/// Why a name is not a valid ROS 2 name: the rule it breaks, and where.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{rule}")]
pub struct NameError {
    /// The rule.
    pub rule: Rule,
    /// The bytes of the name that break it (empty only for an empty name).
    pub at: Range<usize>,
}

fn fail<T>(rule: Rule, at: Range<usize>) -> Result<T, NameError> {
    Err(NameError { rule, at })
}

/// The byte range of the character at byte `i` of `name`.
fn char_at(name: &str, i: usize) -> Range<usize> {
    i..i + name[i..].chars().next().map_or(0, char::len_utf8)
}

/// Check a topic name as a spec writes it: relative (`pose`, `odom/pose`),
/// absolute (`/pose`) or private (`~`, `~/pose`). Tokens (between `/`) are
/// letters, digits and single `_`, not starting with a digit; no empty token,
/// no trailing `/`, no `_` just before a `/`, no substitution. Its fully
/// qualified length is [`check_full_topic`]'s.
pub fn check_topic(name: &str) -> Result<(), NameError> {
    if name.is_empty() {
        return fail(Rule::Empty, 0..0);
    }
    if let Some(i) = name.find(['{', '}']) {
        let end = name[i..].find('}').map_or(i + 1, |k| i + k + 1);
        return fail(Rule::Substitution, i..end);
    }
    if name == "~" {
        return Ok(());
    }
    let (body, offset) = if let Some(rest) = name.strip_prefix("~/") {
        (rest, 2)
    } else if name.starts_with('~') {
        return fail(Rule::Tilde, 0..1);
    } else if let Some(rest) = name.strip_prefix('/') {
        (rest, 1)
    } else {
        (name, 0)
    };
    tokens(body, offset, name.len())
}

/// Check the tokens of `body`, which starts at byte `offset` of a name of
/// `len` bytes (for the positions of errors).
fn tokens(body: &str, offset: usize, len: usize) -> Result<(), NameError> {
    if body.is_empty() || body.ends_with('/') {
        return fail(Rule::TrailingSlash, len - 1..len);
    }
    let mut start = offset;
    let mut rest = body;
    loop {
        let (token, more) = match rest.split_once('/') {
            Some((token, more)) => (token, Some(more)),
            None => (rest, None),
        };
        if token.is_empty() {
            return fail(Rule::EmptyToken, start.saturating_sub(1)..start + 1);
        }
        token_rules(token, start)?;
        let end = start + token.len();
        match more {
            Some(_) if token.ends_with('_') => {
                return fail(Rule::UnderscoreBeforeSlash, end - 1..end + 1);
            }
            Some(more) => {
                rest = more;
                start = end + 1;
            }
            None => return Ok(()),
        }
    }
}

/// A token at byte `at`: letters, digits and single `_`, not starting with a
/// digit.
fn token_rules(token: &str, at: usize) -> Result<(), NameError> {
    let mut previous = None;
    for (i, c) in token.char_indices() {
        if c == '~' {
            return fail(Rule::Tilde, at + i..at + i + 1);
        }
        if !(c.is_ascii_alphanumeric() || c == '_') {
            return fail(Rule::Character(c), at + i..at + i + c.len_utf8());
        }
        if i == 0 && c.is_ascii_digit() {
            return fail(Rule::StartsWithDigit, at..at + 1);
        }
        if c == '_' && previous == Some('_') {
            return fail(Rule::DoubleUnderscore, at + i - 1..at + i + 1);
        }
        previous = Some(c);
    }
    Ok(())
}

/// Check a fully qualified topic name (what [`expand_topic`] makes): absolute,
/// the tokens of [`check_topic`], at most [`TOPIC_NAME_MAX`] bytes.
pub fn check_full_topic(name: &str) -> Result<(), NameError> {
    absolute(name)?;
    at_most(name, TOPIC_NAME_MAX)
}

/// Check a namespace: `/`, or absolute with the tokens of [`check_topic`], not
/// ending with `_` (a relative topic follows it after a `/`), at most
/// [`NAMESPACE_MAX`] bytes.
pub fn check_namespace(name: &str) -> Result<(), NameError> {
    if name == "/" {
        return Ok(());
    }
    if let Some(i) = name.find(['{', '}']) {
        return fail(Rule::Substitution, i..i + 1);
    }
    absolute(name)?;
    if name.ends_with('_') {
        return fail(Rule::TrailingUnderscore, name.len() - 1..name.len());
    }
    at_most(name, NAMESPACE_MAX)
}

/// `name` starts with `/` and its tokens follow [`check_topic`]'s rules.
fn absolute(name: &str) -> Result<(), NameError> {
    if name.is_empty() {
        return fail(Rule::Empty, 0..0);
    }
    let Some(body) = name.strip_prefix('/') else {
        return fail(Rule::NotAbsolute, char_at(name, 0));
    };
    tokens(body, 1, name.len())
}

/// `name` has at most `max` bytes.
fn at_most(name: &str, max: usize) -> Result<(), NameError> {
    if name.len() > max {
        let at = floor_char(name, max)..name.len();
        return fail(
            Rule::TooLong {
                len: name.len(),
                max,
            },
            at,
        );
    }
    Ok(())
}

/// `at` moved back to a character boundary of `name`.
fn floor_char(name: &str, mut at: usize) -> usize {
    while !name.is_char_boundary(at) {
        at -= 1;
    }
    at
}

/// Check a node name: letters, digits and `_`, not starting with a digit, at
/// most [`NODE_NAME_MAX`] bytes.
pub fn check_node(name: &str) -> Result<(), NameError> {
    if name.is_empty() {
        return fail(Rule::Empty, 0..0);
    }
    if let Some((i, c)) = name
        .char_indices()
        .find(|(_, c)| !(c.is_ascii_alphanumeric() || *c == '_'))
    {
        return fail(Rule::Character(c), char_at(name, i));
    }
    if name.starts_with(|c: char| c.is_ascii_digit()) {
        return fail(Rule::StartsWithDigit, 0..1);
    }
    at_most(name, NODE_NAME_MAX)
}

/// Check a package name (REP 144, `rosidl`): lowercase letters, digits and
/// single `_`, starting with a letter, not ending with `_`, at least 2
/// characters.
pub fn check_package(name: &str) -> Result<(), NameError> {
    if name.is_empty() {
        return fail(Rule::Empty, 0..0);
    }
    let mut previous = None;
    for (i, c) in name.char_indices() {
        if c.is_ascii_uppercase() {
            return fail(Rule::Uppercase(c), i..i + 1);
        }
        if !(c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_') {
            return fail(Rule::Character(c), char_at(name, i));
        }
        if i == 0 && c.is_ascii_digit() {
            return fail(Rule::StartsWithDigit, 0..1);
        }
        if i == 0 && c == '_' {
            return fail(Rule::StartsWithUnderscore, 0..1);
        }
        if c == '_' && previous == Some('_') {
            return fail(Rule::DoubleUnderscore, i - 1..i + 1);
        }
        previous = Some(c);
    }
    if name.ends_with('_') {
        return fail(Rule::TrailingUnderscore, name.len() - 1..name.len());
    }
    if name.len() < 2 {
        return fail(Rule::TooShort, 0..name.len());
    }
    Ok(())
}

/// Check a message type: `package/msg/Type`, the package as
/// [`check_package`], the type name an uppercase letter then letters and
/// digits (`rosidl`'s rule).
pub fn check_message(name: &str) -> Result<(), NameError> {
    if name.is_empty() {
        return fail(Rule::Empty, 0..0);
    }
    let parts: Vec<&str> = name.split('/').collect();
    let [package, middle, ty] = parts[..] else {
        return fail(Rule::MessageForm, 0..name.len());
    };
    if package.is_empty() {
        return fail(Rule::MessageForm, 0..name.len());
    }
    check_package(package)?;
    let middle_at = package.len() + 1;
    if middle != "msg" {
        return fail(Rule::NotMsg, middle_at..middle_at + middle.len().max(1));
    }
    let ty_at = middle_at + middle.len() + 1;
    let Some(first) = ty.chars().next() else {
        return fail(Rule::MessageForm, 0..name.len());
    };
    if !first.is_ascii_uppercase() {
        return fail(Rule::TypeStart(first), char_at(name, ty_at));
    }
    if let Some((i, c)) = ty.char_indices().find(|(_, c)| !c.is_ascii_alphanumeric()) {
        return fail(Rule::Character(c), char_at(name, ty_at + i));
    }
    Ok(())
}

/// The fully qualified name of `topic` (as [`check_topic`] accepts it) for a
/// node `node` in namespace `namespace`: an absolute topic as it is, `~` the
/// node's own name in its namespace, a relative topic in the namespace.
pub fn expand_topic(topic: &str, node: &str, namespace: &str) -> String {
    let within = |name: &str| {
        if namespace.ends_with('/') {
            format!("{namespace}{name}")
        } else {
            format!("{namespace}/{name}")
        }
    };
    if topic.starts_with('/') {
        topic.to_owned()
    } else if topic == "~" {
        within(node)
    } else if let Some(rest) = topic.strip_prefix("~/") {
        format!("{}/{rest}", within(node))
    } else {
        within(topic)
    }
}

/// A topic's quality of service, every policy decided.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct QosProfile {
    /// Reliable or best effort.
    pub reliability: Reliability,
    /// Keep-last depth.
    pub depth: u32,
    /// Volatile or transient local.
    pub durability: Durability,
}

impl QosProfile {
    /// The quality of service that matches a link's policy: a queue of `n` is
    /// reliable with depth `n` (nothing lost, as in the queue); a sample is
    /// best effort with depth 1 (the latest value wins); a buffer without link
    /// (`None`) is reliable with depth 1. Always volatile.
    pub fn of_link(policy: Option<Policy>) -> QosProfile {
        let (reliability, depth) = match policy {
            Some(Policy::Queue { bound }) => (
                Reliability::Reliable,
                u32::try_from(bound).unwrap_or(u32::MAX),
            ),
            Some(Policy::Sample) => (Reliability::BestEffort, 1),
            None => (Reliability::Reliable, 1),
        };
        QosProfile {
            reliability,
            depth,
            durability: Durability::Volatile,
        }
    }

    /// These policies, each replaced by the one `qos` gives, if it gives it.
    pub fn with(self, qos: Option<&Qos>) -> QosProfile {
        let Some(qos) = qos else { return self };
        QosProfile {
            reliability: qos.reliability.unwrap_or(self.reliability),
            depth: qos.depth.unwrap_or(self.depth),
            durability: qos.durability.unwrap_or(self.durability),
        }
    }
}

/// The policy of the links of buffer `buffer` (`component.group.buffer`), an
/// output (`output`) or an input: the largest queue among the links that read
/// or feed it, else sample (a checked spec feeds an input by one link only).
/// `None` when no link has it.
pub fn link_policy(spec: &Spec, buffer: &str, output: bool) -> Option<Policy> {
    let mut policies = spec
        .links
        .iter()
        .filter(|l| (if output { &l.from } else { &l.to }) == buffer)
        .map(|l| l.policy);
    let first = policies.next()?;
    Some(policies.fold(first, |a, b| match (a, b) {
        (Policy::Queue { bound: x }, Policy::Queue { bound: y }) => Policy::queue(x.max(y)),
        (q @ Policy::Queue { .. }, Policy::Sample) | (Policy::Sample, q) => q,
    }))
}

/// The `ros2` section that applies to `deployment` (its own, else the
/// system's), or the system's when `deployment` is `None`.
pub fn section<'s>(spec: &'s Spec, deployment: Option<&'s Deployment>) -> Option<&'s Ros2> {
    deployment
        .and_then(|d| d.ros2.as_ref())
        .or(spec.ros2.as_ref())
}

/// Where, in `text` (the spec's source), the entry of the `ros2` section
/// that applies to `deployment` ([`section`]) showing `buffer` is: the span
/// of its `buffer` value, the published entry's if both sides show it. For
/// what only a program can find (a buffer's Rust type that cannot be the
/// message: [`Code::Ros2Type`](crate::Code::Ros2Type)), said in the
/// checker's format. `None` when no entry shows `buffer`, or the text does
/// not parse.
pub fn entry_span(
    spec: &Spec,
    text: &str,
    deployment: Option<&str>,
    buffer: &str,
) -> Option<Range<usize>> {
    use crate::span::Seg::{Field, Item};
    let d = deployment.and_then(|name| spec.deployments.iter().position(|d| d.name == name));
    let own = d.filter(|&d| spec.deployments[d].ros2.is_some());
    let (mut path, ros2) = match own {
        Some(d) => (
            vec![Field("deployments"), Item(d), Field("ros2")],
            spec.deployments[d].ros2.as_ref()?,
        ),
        None => (vec![Field("ros2")], spec.ros2.as_ref()?),
    };
    let (side, k) = [("publish", &ros2.publish), ("subscribe", &ros2.subscribe)]
        .into_iter()
        .find_map(|(side, entries)| {
            Some((side, entries.iter().position(|e| e.buffer == buffer)?))
        })?;
    path.extend([Field(side), Item(k), Field("buffer")]);
    Some(crate::span::parse(text)?.at(&path)?.content_span())
}

/// The node a `ros2` section of `spec` names: its own, else the system's name.
pub fn node_of<'s>(spec: &'s Spec, section: &'s Ros2) -> &'s str {
    section.node.as_deref().unwrap_or(&spec.name)
}

/// The namespace a `ros2` section names: its own, else `/`.
pub fn namespace_of(section: &Ros2) -> &str {
    section.namespace.as_deref().unwrap_or("/")
}

/// The package a `ros2` section names: its own, else `<system name>_msgs`.
pub fn package_of(spec: &Spec, section: &Ros2) -> String {
    section
        .package
        .clone()
        .unwrap_or_else(|| format!("{}_msgs", spec.name))
}

/// What a system or one of its deployments shows to ROS 2, every default
/// applied.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Interface {
    /// `ROS_DOMAIN_ID`.
    pub domain: u32,
    /// The node's name.
    pub node: String,
    /// The node's namespace.
    pub namespace: String,
    /// The package of the messages made from buffer types.
    pub package: String,
    /// The output buffers published.
    pub publish: Vec<Topic>,
    /// The input buffers fed by topics.
    pub subscribe: Vec<Topic>,
}

/// One buffer on one topic.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Topic {
    /// The buffer, `component.group.buffer`.
    pub buffer: String,
    /// Its component.
    pub component: String,
    /// Its type, as the spec writes it.
    pub ty: String,
    /// The topic's fully qualified name (`/rex/pose`).
    pub name: String,
    /// The standard message the spec names, or `None`: the message made from
    /// the buffer's type, in the interface's package.
    pub message: Option<String>,
    /// Its quality of service.
    pub qos: QosProfile,
}

/// What `spec` shows to ROS 2 when `deployment` runs (`None`: the whole
/// system), or `None` if it shows nothing. Entries whose component the
/// deployment does not run are left out, and so are entries naming no buffer
/// (the checker reports those). Meant for a spec the checker passed.
pub fn interface(spec: &Spec, deployment: Option<&Deployment>) -> Option<Interface> {
    let section = section(spec, deployment)?;
    let node = node_of(spec, section).to_owned();
    let namespace = namespace_of(section).to_owned();
    let topics = |entries: &[Ros2Topic], output: bool| -> Vec<Topic> {
        entries
            .iter()
            .flat_map(|entry| {
                crate::fans::elements(spec, &entry.buffer)
                    .into_iter()
                    .map(move |(buffer, k)| (entry, buffer, k))
            })
            .filter_map(|(entry, buffer, k)| {
                let (component, ty) = buffer_type(spec, &buffer, output)?;
                let runs = deployment.is_none_or(|d| d.runs().any(|r| r == component));
                let name = element_topic(&expand_topic(&entry.topic, &node, &namespace), k);
                runs.then(|| Topic {
                    component: component.to_owned(),
                    ty: ty.to_owned(),
                    name,
                    message: entry.message.clone(),
                    qos: QosProfile::of_link(link_policy(spec, &buffer, output))
                        .with(entry.qos.as_ref()),
                    buffer,
                })
            })
            .collect()
    };
    Some(Interface {
        domain: section.domain.unwrap_or(0),
        publish: topics(&section.publish, true),
        subscribe: topics(&section.subscribe, false),
        package: package_of(spec, section),
        node,
        namespace,
    })
}

/// The topic of element `k` of an entry naming a whole fan (`[*]`), given
/// the entry's (fully qualified) topic: `topic_k` (`/x/plans` -> `/x/plans_3`;
/// a topic's token may not start with a digit, so the index is joined to its
/// last token); `topic` itself for an entry naming one buffer.
pub fn element_topic(topic: &str, k: Option<usize>) -> String {
    k.map_or_else(|| topic.to_owned(), |k| format!("{topic}_{k}"))
}

/// The component and type of buffer `component.group.buffer` among the
/// outputs (`output`) or inputs of its component; a fan's element is
/// `component.fan[k].buffer` (a whole fan, `[*]`, is its element 0's).
pub fn buffer_type<'s>(spec: &'s Spec, buffer: &str, output: bool) -> Option<(&'s str, &'s str)> {
    let one = crate::fans::element(buffer, 0);
    let parts: Vec<&str> = one.split('.').collect();
    let [component, peer, name] = parts[..] else {
        return None;
    };
    // `c1[3]`: element 3 of fan `c1`, which must have it.
    let (peer, index) = match peer.split_once('[') {
        Some((fan, rest)) => (fan, Some(rest.strip_suffix(']')?.parse::<usize>().ok()?)),
        None => (peer, None),
    };
    let groups = spec.agents.iter().find_map(|a| {
        let side = |inputs, outputs| if output { outputs } else { inputs };
        a.subsystems
            .iter()
            .find(|s| s.name == component)
            .map(|s| (s.name.as_str(), side(&s.inputs, &s.outputs)))
            .or_else(|| {
                a.devices
                    .iter()
                    .find(|d| d.name == component)
                    .map(|d| (d.name.as_str(), side(&d.inputs, &d.outputs)))
            })
    });
    let (component, groups) = groups?;
    groups
        .iter()
        .filter(|g| g.peer == peer && index.map_or(g.peers.is_empty(), |k| k < g.peers.len()))
        .flat_map(|g| &g.buffers)
        .find(|b| b.name == name)
        .map(|b| (component, b.ty.as_str()))
}

#[cfg(test)]
mod tests;
