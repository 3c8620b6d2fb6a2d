//! The `ros2` sections, the system's and each deployment's: ROS 2's name rules
//! ([`crate::ros2`]), the buffers they show (existing, on the right side, run by
//! the deployment), topics given twice, and topics that a sample link would
//! overwrite.

use super::*;
use crate::model::{Deployment, Ros2, Ros2Topic};
use crate::ros2::{self as rules, NameError, Rule};

/// A `ros2` section, where it is, and the deployment it belongs to (`None`:
/// the system's, shown by every deployment without its own).
struct Section<'a> {
    ros2: &'a Ros2,
    path: Path,
    deployment: Option<&'a Deployment>,
}

/// A topic of a section as the duplicate check sees it.
struct Shown {
    /// The fully qualified name (as written when the node's names are invalid).
    name: String,
    /// The entry's path.
    path: Path,
    /// Published (else subscribed).
    output: bool,
    /// Whether its buffer is one the section may show.
    buffer_valid: bool,
    /// Its buffer: the entry's, or one element's of a whole fan (`[*]`).
    buffer: String,
}

/// What a name is, for messages and help lines.
#[derive(Clone, Copy)]
enum Kind {
    Topic,
    Node,
    Namespace,
    Package,
    Message,
}

impl Kind {
    fn what(self) -> &'static str {
        match self {
            Kind::Topic => "topic",
            Kind::Node => "node",
            Kind::Namespace => "namespace",
            Kind::Package => "package",
            Kind::Message => "message type",
        }
    }

    fn help(self) -> &'static str {
        match self {
            Kind::Topic => {
                "a topic is relative (`pose`), absolute (`/pose`) or private to the node (`~/pose`); its tokens, between single `/`, are letters, digits and single `_`, not starting with a digit; specs write no substitutions `{...}`"
            }
            Kind::Node => {
                "a node name is letters, digits and `_`, not starting with a digit, at most 255 bytes"
            }
            Kind::Namespace => {
                "a namespace is `/` or absolute like `/lab/rex`: tokens of letters, digits and single `_`, not starting with a digit; no trailing `/` or `_`"
            }
            Kind::Package => {
                "a package name (REP 144) is lowercase letters, digits and single `_`, starting with a letter, not ending with `_`, at least 2 characters"
            }
            Kind::Message => {
                "a message type is `package/msg/Type`, such as `geometry_msgs/msg/PoseStamped`"
            }
        }
    }
}

/// A few words under the offending part of a name.
fn label(rule: &Rule) -> String {
    match rule {
        Rule::Empty => "empty".into(),
        Rule::Character(c) => format!("`{}` not allowed", c.escape_debug()),
        Rule::Uppercase(_) => "uppercase".into(),
        Rule::StartsWithDigit => "starts with a digit".into(),
        Rule::StartsWithUnderscore => "starts with `_`".into(),
        Rule::EmptyToken => "empty token".into(),
        Rule::TrailingSlash => "trailing `/`".into(),
        Rule::DoubleUnderscore => "`__`".into(),
        Rule::UnderscoreBeforeSlash => "`_` before `/`".into(),
        Rule::TrailingUnderscore => "trailing `_`".into(),
        Rule::Tilde => "misplaced `~`".into(),
        Rule::Substitution => "substitution".into(),
        Rule::NotAbsolute => "not absolute".into(),
        Rule::TooLong { .. } => "too long".into(),
        Rule::TooShort => "too short".into(),
        Rule::MessageForm => "not `package/msg/Type`".into(),
        Rule::NotMsg => "not `msg`".into(),
        Rule::TypeStart(_) => "not an uppercase letter".into(),
    }
}

impl<'a> Checker<'a> {
    /// The system's `ros2` section and each deployment's.
    pub(super) fn ros2(&mut self) {
        let spec = self.spec;
        if let Some(ros2) = &spec.ros2 {
            self.ros2_section(&Section {
                ros2,
                path: vec![F("ros2")],
                deployment: None,
            });
        }
        for (d, dep) in spec.deployments.iter().enumerate() {
            if let Some(ros2) = &dep.ros2 {
                self.ros2_section(&Section {
                    ros2,
                    path: vec![F("deployments"), I(d), F("ros2")],
                    deployment: Some(dep),
                });
            }
        }
    }

    fn ros2_section(&mut self, s: &Section<'a>) {
        let names_valid = self.ros2_names(s);
        let node = rules::node_of(self.spec, s.ros2);
        let namespace = rules::namespace_of(s.ros2);
        let mut shown = Vec::new();
        for (side, output, entries) in [
            ("publish", true, &s.ros2.publish),
            ("subscribe", false, &s.ros2.subscribe),
        ] {
            for (k, entry) in entries.iter().enumerate() {
                let path = join(&s.path, &[F(side), I(k)]);
                let component = self.ros2_buffer(s, entry, &path, output);
                let name = self.ros2_topic(entry, &path, names_valid.then_some((node, namespace)));
                if let Some(name) = name {
                    self.ros2_shown(&mut shown, name, &path, output, component.is_some(), entry);
                }
                if let Some(message) = &entry.message {
                    let at = join(&path, &[F("message")]);
                    self.ros2_name(rules::check_message(message), message, &at, Kind::Message);
                }
                if entry.qos.and_then(|q| q.depth) == Some(0) {
                    self.ros2_depth(&join(&path, &[F("qos"), F("depth")]), &entry.topic);
                }
                // Per element of a whole fan (`[*]`): each its own topic.
                let elements = component.map_or_else(Vec::new, |_| {
                    crate::fans::elements(self.spec, &entry.buffer)
                });
                for (buffer, k) in elements {
                    let one = Ros2Topic {
                        buffer,
                        topic: rules::element_topic(&entry.topic, k),
                        ..entry.clone()
                    };
                    match component {
                        Some(component) if !output => {
                            self.ros2_overwritten(s, &one, &path, component);
                        }
                        _ => self.ros2_unlinked(&one, &path),
                    }
                }
            }
        }
        self.ros2_duplicates(&shown);
    }

    /// The topics entry `entry` (at `path`, its full topic `name`) shows, for
    /// the duplicate check: its topic, or for a whole fan (`[*]`) each
    /// element's, `name_k`, whose full name must follow ROS 2's rules too.
    fn ros2_shown(
        &mut self,
        shown: &mut Vec<Shown>,
        name: String,
        path: &[Seg<'static>],
        output: bool,
        buffer_valid: bool,
        entry: &'a Ros2Topic,
    ) {
        let mut elements = crate::fans::elements(self.spec, &entry.buffer);
        if elements.is_empty() {
            // A whole fan the component lacks: reported with the buffer.
            elements.push((entry.buffer.clone(), None));
        }
        for (buffer, k) in elements {
            let name = rules::element_topic(&name, k);
            if k == Some(0)
                && let Err(e) = rules::check_full_topic(&name)
            {
                self.push(
                    Finding::new(
                        Code::Ros2Name,
                        self.span(&join(path, &[F("topic")])),
                        format!("`{}` for element 0", abbreviate(&name, 60)),
                        format!(
                            "topic `{}` of every element of a fan is `{}` for element 0, which breaks ROS 2's naming rules: {e}",
                            abbreviate(&entry.topic, 60),
                            abbreviate(&name, 60)
                        ),
                    )
                    .help("each element's topic is the topic with `_k` joined to it: end the topic with a letter or a digit, or shorten it"),
                );
            }
            shown.push(Shown {
                name,
                path: path.to_vec(),
                output,
                buffer_valid,
                buffer,
            });
        }
    }

    /// The domain, node, namespace and package of section `s`; whether the
    /// node and namespace are valid (topics can then be expanded).
    fn ros2_names(&mut self, s: &Section<'a>) -> bool {
        let spec = self.spec;
        if let Some(domain) = s.ros2.domain.filter(|d| *d > rules::DOMAIN_MAX) {
            self.push(
                Finding::new(
                    Code::Ros2Domain,
                    self.span(&join(&s.path, &[F("domain")])),
                    format!("above {}", rules::DOMAIN_MAX),
                    format!("ROS 2 domain {domain} is out of range (0 to {})", rules::DOMAIN_MAX),
                )
                .help("ROS_DOMAIN_ID is 0 to 232 (0 to 101 is safe on every platform); leave `domain` out for 0"),
            );
        }
        let node = match &s.ros2.node {
            Some(node) => self.ros2_name(
                rules::check_node(node),
                node,
                &join(&s.path, &[F("node")]),
                Kind::Node,
            ),
            None => self.ros2_default(s, rules::check_node(&spec.name), &spec.name, Kind::Node),
        };
        let namespace = match &s.ros2.namespace {
            Some(ns) => self.ros2_name(
                rules::check_namespace(ns),
                ns,
                &join(&s.path, &[F("namespace")]),
                Kind::Namespace,
            ),
            None => true,
        };
        match &s.ros2.package {
            Some(package) => {
                let at = join(&s.path, &[F("package")]);
                self.ros2_name(rules::check_package(package), package, &at, Kind::Package);
            }
            None => {
                let package = rules::package_of(spec, s.ros2);
                self.ros2_default(s, rules::check_package(&package), &package, Kind::Package);
            }
        }
        node && namespace
    }

    /// Report `result`, the check of the `kind` name `name` at `path`, with a
    /// label on the part that breaks the rule; whether it passed.
    fn ros2_name(
        &mut self,
        result: Result<(), NameError>,
        name: &str,
        path: &[Seg<'static>],
        kind: Kind,
    ) -> bool {
        let Err(e) = result else { return true };
        let span = match self.node(path) {
            Some(node) => Some(node.sub_span(e.at.clone()))
                .filter(|s| !s.is_empty())
                .unwrap_or_else(|| node.span.clone()),
            None => self.span(path),
        };
        self.push(
            Finding::new(
                Code::Ros2Name,
                span,
                label(&e.rule),
                format!(
                    "{} `{}` breaks ROS 2's naming rules: {e}",
                    kind.what(),
                    abbreviate(name, 60)
                ),
            )
            .help(kind.help()),
        );
        false
    }

    /// Report `result`, the check of the default `kind` name `name` that
    /// section `s` takes from the system's name; whether it passed.
    fn ros2_default(
        &mut self,
        s: &Section<'a>,
        result: Result<(), NameError>,
        name: &str,
        kind: Kind,
    ) -> bool {
        let Err(e) = result else { return true };
        let field = match kind {
            Kind::Node => "node",
            _ => "package",
        };
        self.push(
            Finding::new(
                Code::Ros2Name,
                self.key_span(&s.path),
                format!("no `{field}`"),
                format!(
                    "the default {} `{}`, made from the system's name, breaks ROS 2's naming rules: {e}",
                    kind.what(),
                    abbreviate(name, 60)
                ),
            )
            .label(self.span(&[F("name")]), "the system's name")
            .help(format!("give the section a `{field}: \"...\"`; {}", kind.help())),
        );
        false
    }

    /// A keep-last depth of 0 at `path`, of the entry for `topic`.
    fn ros2_depth(&mut self, path: &[Seg<'static>], topic: &str) {
        self.push(
            Finding::new(
                Code::Ros2Qos,
                self.span(path),
                "keeps nothing",
                format!("topic `{}` keeps the last 0 samples", abbreviate(topic, 60)),
            )
            .help(
                "a depth is at least 1; leave it out to take the link's (a queue's bound, else 1)",
            ),
        );
    }

    /// The topic of `entry` (at `path`): its name rules, then its fully
    /// qualified name (when `names`, the node and namespace, are valid) and
    /// that name's length. The name to compare with the others, if valid.
    fn ros2_topic(
        &mut self,
        entry: &Ros2Topic,
        path: &[Seg<'static>],
        names: Option<(&str, &str)>,
    ) -> Option<String> {
        let at = join(path, &[F("topic")]);
        if !self.ros2_name(
            rules::check_topic(&entry.topic),
            &entry.topic,
            &at,
            Kind::Topic,
        ) {
            return None;
        }
        let Some((node, namespace)) = names else {
            return Some(entry.topic.clone());
        };
        let full = rules::expand_topic(&entry.topic, node, namespace);
        if let Err(e) = rules::check_full_topic(&full) {
            self.push(
                Finding::new(
                    Code::Ros2Name,
                    self.span(&at),
                    format!("`{}` in full", abbreviate(&full, 60)),
                    format!(
                        "topic `{}` is `{}` in full, which breaks ROS 2's naming rules: {e}",
                        abbreviate(&entry.topic, 60),
                        abbreviate(&full, 60)
                    ),
                )
                .help("the node's namespace and name come before a relative or private topic; shorten or rename them, or give an absolute topic"),
            );
            return None;
        }
        Some(full)
    }
}

impl<'a> Checker<'a> {
    /// The buffer of `entry` (at `path`) of section `s`: an output to publish
    /// or an input to feed, of a component the section's deployment runs. Its
    /// component, if it is all that.
    fn ros2_buffer(
        &mut self,
        s: &Section<'a>,
        entry: &Ros2Topic,
        path: &[Seg<'static>],
        output: bool,
    ) -> Option<&'a str> {
        let at = join(path, &[F("buffer")]);
        let text = entry.buffer.as_str();
        let (side, kind) = if output {
            ("publish", "output")
        } else {
            ("subscribe", "input")
        };
        let f = match self.endpoint(&self.one_element(text), output) {
            Ok((component, _, _)) => match s.deployment {
                Some(dep) if !dep.runs().any(|r| r == component) => {
                    self.ros2_not_deployed(dep, component, text, &at)
                }
                _ => return Some(component),
            },
            Err(EndpointError::Form) => Finding::new(
                Code::UnknownBuffer,
                self.span(&at),
                "not `component.group.buffer`",
                format!(
                    "ROS 2 `{side}` entry `{}` is not of the form `component.group.buffer`",
                    abbreviate(text, 60)
                ),
            )
            .help(
                "name the component, the group's peer and the buffer, as in a link: `c1.e11.traj`",
            ),
            Err(EndpointError::Component(c)) => {
                let known = self.known_components();
                let guess = self.guess_component(&c);
                Finding::new(
                    Code::UnknownComponent,
                    self.span(&at),
                    "no such component",
                    format!(
                        "ROS 2 `{side}` entry `{}` names component `{c}`, which does not exist",
                        abbreviate(text, 60)
                    ),
                )
                .help(format!("{guess}components: {known}"))
            }
            Err(EndpointError::Direction) => {
                let (is, move_to) = if output {
                    ("an input", "subscribe")
                } else {
                    ("an output", "publish")
                };
                Finding::new(
                    Code::Ros2Direction,
                    self.span(&at),
                    format!("{is}, not {}", if output { "an output" } else { "an input" }),
                    format!("ROS 2 `{side}` entry `{text}` is {is} buffer: `{side}` takes {} buffer", if output { "an output" } else { "an input" }),
                )
                .help(format!("`publish` shows an output (a link's `from`), `subscribe` feeds an input (a link's `to`); move the entry to `{move_to}` if that is what you mean"))
            }
            Err(EndpointError::Buffer) => match self.fan_problem(text, output) {
                Some((label, message, help)) => {
                    Finding::new(Code::UnknownBuffer, self.span(&at), label, message).help(help)
                }
                None => self.ros2_unknown_buffer(text, &at, side, kind, output),
            },
        };
        self.push(f);
        None
    }

    /// The finding about `text` (at `path`, in `side`) that names no `kind`
    /// buffer of its component.
    fn ros2_unknown_buffer(
        &mut self,
        text: &str,
        path: &[Seg<'static>],
        side: &str,
        kind: &str,
        output: bool,
    ) -> Finding {
        let (component, rest) = text.split_once('.').unwrap_or((text, ""));
        let have = self.buffers_on_side(component, output);
        let guess = self.guess(rest, have.iter().map(String::as_str));
        let list = list_or_none(&have.iter().map(String::as_str).collect::<Vec<_>>());
        Finding::new(
            Code::UnknownBuffer,
            self.span(path),
            "no such buffer",
            format!(
                "ROS 2 `{side}` entry `{}` names no {kind} buffer of `{component}`",
                abbreviate(text, 60)
            ),
        )
        .help(format!("{guess}`{component}`'s {kind}s: {list}"))
    }

    /// The finding about buffer `text` (at `path`) of `component`, which
    /// deployment `dep` does not run.
    fn ros2_not_deployed(
        &self,
        dep: &Deployment,
        component: &str,
        text: &str,
        path: &[Seg<'static>],
    ) -> Finding {
        let how = if dep.omit.iter().any(|o| o == component) {
            "omits"
        } else {
            "does not run"
        };
        Finding::new(
            Code::Ros2NotDeployed,
            self.span(path),
            format!("`{component}` is not run"),
            format!(
                "deployment `{}` {how} `{component}`, yet its `ros2` section shows `{text}`",
                dep.name
            ),
        )
        .help(format!(
            "remove the entry, or run `{component}` in a process of `{}`",
            dep.name
        ))
    }

    /// Topics given twice, by their full names, and inputs fed by two topics.
    fn ros2_duplicates(&mut self, shown: &[Shown]) {
        let mut topics: HashMap<&str, &Shown> = HashMap::new();
        let mut inputs: HashMap<&str, &Shown> = HashMap::new();
        for t in shown {
            match topics.get(t.name.as_str()) {
                Some(first) => {
                    let f = self.ros2_topic_twice(first, t);
                    self.push(f);
                }
                None => {
                    topics.insert(&t.name, t);
                }
            }
            if t.output || !t.buffer_valid {
                continue;
            }
            match inputs.get(t.buffer.as_str()) {
                Some(first) => self.push(
                    Finding::new(
                        Code::Ros2Duplicate,
                        self.span(&join(&t.path, &[F("buffer")])),
                        "fed again",
                        format!(
                            "input `{}` is fed by two topics, `{}` and `{}`",
                            t.buffer, first.name, t.name
                        ),
                    )
                    .label(
                        self.span(&join(&first.path, &[F("buffer")])),
                        "first fed here",
                    )
                    .help("an input buffer has one writer; keep one of the entries"),
                ),
                None => {
                    inputs.insert(&t.buffer, t);
                }
            }
        }
    }

    /// The finding about topic `t`, which `first` gives already.
    fn ros2_topic_twice(&self, first: &Shown, t: &Shown) -> Finding {
        let (message, help) = match (first.output, t.output) {
            (true, true) => (
                format!(
                    "topic `{}` is published twice, from `{}` and `{}`",
                    t.name, first.buffer, t.buffer
                ),
                "give each buffer its own topic (one buffer may be published under several topics)",
            ),
            (false, false) => (
                format!(
                    "topic `{}` is subscribed twice, into `{}` and `{}`",
                    t.name, first.buffer, t.buffer
                ),
                "a topic feeds one input buffer; give each entry its own topic",
            ),
            _ => {
                let (out, inp) = if first.output { (first, t) } else { (t, first) };
                (
                    format!(
                        "topic `{}` is both published and subscribed: the node would feed its own `{}` back into `{}`",
                        t.name, out.buffer, inp.buffer
                    ),
                    "give the published and the subscribed buffer different topics",
                )
            }
        };
        Finding::new(
            Code::Ros2Duplicate,
            self.span(&join(&t.path, &[F("topic")])),
            "given again",
            message,
        )
        .label(
            self.span(&join(&first.path, &[F("topic")])),
            "first given here",
        )
        .help(help)
    }

    /// Warn when input `entry.buffer` of `consumer`, fed by a topic, is also
    /// written over a sample link by a component that runs beside it where
    /// section `s` applies: the two overwrite each other.
    fn ros2_overwritten(
        &mut self,
        s: &Section<'a>,
        entry: &Ros2Topic,
        path: &[Seg<'static>],
        consumer: &str,
    ) {
        let spec = self.spec;
        let Some((k, link)) = spec
            .links
            .iter()
            .enumerate()
            .find(|(_, l)| l.to == entry.buffer)
        else {
            return;
        };
        if !matches!(link.policy, Policy::Sample) {
            return;
        }
        let producer = link.from.split('.').next().unwrap_or_default();
        let both =
            |d: &Deployment| d.runs().any(|r| r == producer) && d.runs().any(|r| r == consumer);
        let within = match s.deployment {
            Some(dep) if both(dep) => format!("in deployment `{}`", dep.name),
            Some(_) => return,
            None if spec.deployments.is_empty() => "in the system".to_owned(),
            None => {
                let names: Vec<String> = spec
                    .deployments
                    .iter()
                    .filter(|d| d.ros2.is_none() && both(d))
                    .map(|d| format!("`{}`", d.name))
                    .collect();
                match names.len() {
                    0 => return,
                    1 => format!("in deployment {}", names[0]),
                    _ => format!("in deployments {}", names.join(", ")),
                }
            }
        };
        self.push(
            Finding::new(
                Code::Ros2Overwritten,
                self.span(&join(path, &[F("buffer")])),
                "fed by ROS 2 and by a link",
                format!(
                    "input `{}` is fed by topic `{}` and, {within}, by `{}` over a sample link: each value overwrites the other",
                    entry.buffer, entry.topic, link.from
                ),
            )
            .label(self.span(&[F("links"), I(k), F("from")]), "a sample link")
            .help(format!(
                "make the link a queue (`policy: Queue(n)`) to deliver both, omit `{producer}` where ROS 2 feeds the input, or feed another input"
            )),
        );
    }

    /// The finding about published output `entry` (at `path`) if no link
    /// carries its values: the bridge publishes what is sent into a link, and
    /// a value written to an unlinked output is sent nowhere.
    fn ros2_unlinked(&mut self, entry: &Ros2Topic, path: &[Seg<'static>]) {
        if self.spec.links.iter().any(|l| l.from == entry.buffer) {
            return;
        }
        let (component, rest) = entry.buffer.split_once('.').unwrap_or((&entry.buffer, ""));
        let peer = rest.split('.').next().unwrap_or_default();
        self.push(
            Finding::new(
                Code::Ros2Unlinked,
                self.span(&join(path, &[F("buffer")])),
                "no link carries it",
                format!(
                    "topic `{}` would publish output `{}`, but no link carries that output's values: ROS 2 would see none",
                    entry.topic, entry.buffer
                ),
            )
            .help(format!(
                "link the output to the input that reads it (`(from: \"{}\", to: \"{peer}.{component}.…\")`), or publish a linked output",
                entry.buffer
            )),
        );
    }
}
