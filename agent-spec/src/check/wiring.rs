//! Links between buffers and deployments of components.

use super::components::names_at;
use super::*;
use crate::model::{Deployment, Link};

impl<'a> Checker<'a> {
    /// Find `comp.group.buffer`: (component, group peer, buffer type) on `outputs` or
    /// inputs.
    pub(super) fn endpoint(
        &self,
        text: &str,
        outputs: bool,
    ) -> Result<(&'a str, &'a str, &'a str), EndpointError> {
        let parts: Vec<&str> = text.split('.').collect();
        let [comp, group, buffer] = parts[..] else {
            return Err(EndpointError::Form);
        };
        let Some(c) = self.comps.get(comp) else {
            return Err(EndpointError::Component(comp.to_owned()));
        };
        // `c1[3]`: element 3 of fan `c1` (an index the fan lacks names nothing).
        let (group, index) = match group.split_once('[') {
            Some((fan, rest)) => match rest.strip_suffix(']').and_then(fan_index) {
                Some(k) => (fan, Some(k)),
                None => return Err(EndpointError::Buffer),
            },
            None => (group, None),
        };
        let find = |groups: &'a [Group]| {
            groups
                .iter()
                .find(|g| {
                    g.peer == group && index.map_or(g.peers.is_empty(), |k| k < g.peers.len())
                })
                .and_then(|g| g.buffers.iter().find(|b| b.name == buffer).map(|b| (g, b)))
        };
        match find(if outputs { c.outputs } else { c.inputs }) {
            // An element's group is for its own peer.
            Some((g, b)) => Ok((
                c.name,
                index.map_or(g.peer.as_str(), |k| g.peers[k].as_str()),
                b.ty.as_str(),
            )),
            None if find(if outputs { c.inputs } else { c.outputs }).is_some() => {
                Err(EndpointError::Direction)
            }
            None => Err(EndpointError::Buffer),
        }
    }

    /// Every link, then the buffers they feed: each input has exactly one
    /// writer, each output a reader.
    pub(super) fn links(&mut self) {
        let spec = self.spec;
        let mut feeds = Feeds::default();
        for (k, link) in spec.links.iter().enumerate() {
            self.link(k, link, &mut feeds);
        }
        // Inputs: exactly one writer. Outputs: somebody reads.
        let found = self.feed_findings(&feeds);
        self.findings.extend(found);
    }

    /// Link `k`: its ends exist (recording the output it reads and, when both
    /// ends exist, the input it writes), a queue holds at least one value, and
    /// the buffers it joins agree.
    fn link(&mut self, k: usize, link: &Link, feeds: &mut Feeds) {
        let lpath = vec![F("links"), I(k)];
        let from = self.endpoint(&link.from, true);
        let to = self.endpoint(&link.to, false);
        for (res, text, field, outputs) in [
            (&from, &link.from, "from", true),
            (&to, &link.to, "to", false),
        ] {
            if let Err(e) = res {
                self.endpoint_error(e, text, &join(&lpath, &[F(field)]), outputs);
            }
        }
        if let Policy::Queue { bound: 0 } = link.policy {
            self.push(
                Finding::new(
                    Code::QueueBound,
                    self.span(&join(&lpath, &[F("policy")])),
                    "capacity 0",
                    format!(
                        "link `{} -> {}` is a queue of capacity 0",
                        link.from, link.to
                    ),
                )
                .help("a queue holds at least one value; use Queue(n) with n >= 1, or Sample"),
            );
        }
        if let Ok((c, g, _)) = &from {
            feeds
                .read_outputs
                .insert((c.to_string(), g.to_string(), last(&link.from)));
        }
        let (Ok(from), Ok(to)) = (from, to) else {
            return;
        };
        let (tc, tg, _) = to;
        feeds
            .writers
            .entry((tc.to_owned(), tg.to_owned(), last(&link.to)))
            .or_default()
            .push(k);
        self.joined_buffers(&lpath, link, from, to);
    }

    /// The two buffers (component, group peer, type) that the link at `lpath`
    /// joins: their groups name each other, the agent structure allows the
    /// link, and they carry one type.
    fn joined_buffers(
        &mut self,
        lpath: &[Seg<'static>],
        link: &Link,
        (fc, fg, fty): (&str, &str, &str),
        (tc, tg, tty): (&str, &str, &str),
    ) {
        if fg != tc || tg != fc {
            self.push(
                Finding::new(
                    Code::PeerMismatch,
                    self.span(&join(lpath, &[F("to")])),
                    format!("a buffer of `{tc}` for peer `{tg}`"),
                    format!("link `{} -> {}` joins groups that do not name each other: `{fc}`'s group is for `{fg}`, `{tc}`'s group is for `{tg}`", link.from, link.to),
                )
                .label(self.span(&join(lpath, &[F("from")])), format!("a buffer of `{fc}` for peer `{fg}`"))
                .help(format!("link `{fc}.{tc}.<buffer>` to `{tc}.{fc}.<buffer>`")),
            );
        }
        let (sc, dc) = (&self.comps[fc], &self.comps[tc]);
        if let Some(reason) = structure_violation(sc.kind, dc.kind, sc.agent == dc.agent) {
            self.push(
                Finding::new(
                    Code::Structure,
                    self.span(lpath),
                    format!("{} -> {}", sc.kind, dc.kind),
                    format!("link `{} -> {}` breaks the agent structure: {reason}", link.from, link.to),
                )
                .help("see Fig. 2 of the paper: c talks to its e, r and other agents' c; e to its E; r to its R"),
            );
        }
        if normalize_type(fty) != normalize_type(tty) {
            self.push(
                Finding::new(
                    Code::TypeMismatch,
                    self.span(&join(lpath, &[F("to")])),
                    format!("`{tty}`"),
                    format!("link `{} -> {}` joins a `{fty}` output to a `{tty}` input", link.from, link.to),
                )
                .label(self.span(&join(lpath, &[F("from")])), format!("`{fty}`"))
                .help("both ends of a link carry the same type; change one of the buffer declarations"),
            );
        }
    }

    /// The outputs no link reads and the inputs not fed by exactly one link,
    /// component by component in the spec's order.
    fn feed_findings(&self, feeds: &Feeds) -> Vec<Finding> {
        let mut comps: Vec<&Comp<'a>> = self.comps.values().collect();
        comps.sort_by_key(|c| c.path.clone().into_iter().map(seg_key).collect::<Vec<_>>());
        let mut found = Vec::new();
        for c in comps {
            for (side, groups, outgoing) in
                [("inputs", c.inputs, false), ("outputs", c.outputs, true)]
            {
                for (g, group) in groups.iter().enumerate() {
                    for (b, buffer) in group.buffers.iter().enumerate() {
                        let path = join(&c.path, &[F(side), I(g), F("buffers"), I(b), F("name")]);
                        // A fan's buffer once per element, an ordinary group's once.
                        let elements: Vec<Option<usize>> = if group.peers.is_empty() {
                            vec![None]
                        } else {
                            (0..group.peers.len()).map(Some).collect()
                        };
                        for element in elements {
                            let at = BufferRef::new(c.name, group, element, buffer, path.clone());
                            found.extend(if outgoing {
                                self.unread_output(feeds, &at)
                            } else {
                                self.input_feed(feeds, &at)
                            });
                        }
                    }
                }
            }
        }
        found
    }

    /// The finding about output `at` if no link reads it.
    fn unread_output(&self, feeds: &Feeds, at: &BufferRef<'_>) -> Option<Finding> {
        if feeds.read_outputs.contains(&at.key) {
            return None;
        }
        let dotted = &at.dotted;
        Some(
            Finding::new(
                Code::UnreadOutput,
                self.span(&at.path),
                "read by nobody",
                format!("output `{dotted}` is linked to no input"),
            )
            .help(format!(
                "link it: `(from: \"{dotted}\", to: \"{}.{}.{}\")`, or remove it",
                at.peer, at.component, at.buffer.name
            )),
        )
    }

    /// The buffers `component` has on one side (its outputs or its inputs),
    /// as `peer.buffer`: what a finding on an unknown buffer lists and guesses from.
    pub(super) fn buffers_on_side(&self, component: &str, outputs: bool) -> Vec<String> {
        let groups = self
            .comps
            .get(component)
            .map_or(&[][..], |c| if outputs { c.outputs } else { c.inputs });
        groups
            .iter()
            .flat_map(|g| {
                g.buffers
                    .iter()
                    .map(move |b| format!("{}.{}", g.peer, b.name))
            })
            .collect()
    }

    /// The finding about input `at` unless exactly one link writes it.
    fn input_feed(&self, feeds: &Feeds, at: &BufferRef<'_>) -> Option<Finding> {
        let dotted = &at.dotted;
        match feeds.writers.get(&at.key).map(Vec::as_slice) {
            None | Some([]) => Some(
                Finding::new(
                    Code::UnfedInput,
                    self.span(&at.path),
                    "fed by no output",
                    format!("input `{dotted}` is fed by no output"),
                )
                .help(self.feeding_help(
                    at.component,
                    &at.peer,
                    at.buffer,
                    dotted,
                    &feeds.read_outputs,
                )),
            ),
            Some([_]) => None,
            Some(ks) => {
                let mut f = Finding::new(
                    Code::MultipleWriters,
                    self.span(&at.path),
                    format!("fed by {} outputs", ks.len()),
                    format!("input `{dotted}` is fed by {} outputs", ks.len()),
                )
                .help("an input buffer has exactly one writer; remove all links to it but one");
                for &k in ks {
                    f = f.label(self.span(&[F("links"), I(k), F("from")]), "writes it");
                }
                Some(f)
            }
        }
    }

    pub(super) fn endpoint_error(
        &mut self,
        e: &EndpointError,
        text: &str,
        path: &[Seg<'static>],
        outputs: bool,
    ) {
        let side = if outputs { "an output" } else { "an input" };
        let f = match e {
            EndpointError::Form => Finding::new(
                Code::UnknownBuffer,
                self.span(path),
                "not `component.group.buffer`",
                format!("link end `{text}` is not of the form `component.group.buffer`"),
            )
            .help("name the component, the group's peer and the buffer, e.g. `c1.e11.traj`"),
            EndpointError::Component(c) => {
                let known = self.known_components();
                let guess = self.guess_component(c);
                Finding::new(
                    Code::UnknownComponent,
                    self.span(path),
                    "no such component",
                    format!("link end `{text}` names component `{c}`, which does not exist"),
                )
                .help(format!("{guess}components: {known}"))
            }
            EndpointError::Direction => Finding::new(
                Code::LinkDirection,
                self.span(path),
                format!("not {side}"),
                format!(
                    "link end `{text}` must be {side}, but it is {}",
                    if outputs { "an input" } else { "an output" }
                ),
            )
            .help("a link goes from an output buffer (`from`) to an input buffer (`to`)"),
            EndpointError::Buffer if self.fan_problem(text, outputs).is_some() => {
                let (label, message, help) = self.fan_problem(text, outputs).unwrap_or_default();
                Finding::new(Code::UnknownBuffer, self.span(path), label, message).help(help)
            }
            EndpointError::Buffer => {
                // `component.group.buffer`: the buffers it has on that side.
                let (component, rest) = text.split_once('.').unwrap_or((text, ""));
                let have = self.buffers_on_side(component, outputs);
                let guess = self.guess(rest, have.iter().map(String::as_str));
                Finding::new(
                    Code::UnknownBuffer,
                    self.span(path),
                    "no such buffer",
                    format!(
                        "link end `{text}` names no {} buffer",
                        if outputs { "output" } else { "input" }
                    ),
                )
                .help(format!(
                    "{guess}check the group (the peer's name) and the buffer's name"
                ))
            }
        };
        self.push(f);
    }

    /// Why link end `text` names no buffer when a fan is involved: an index
    /// the fan lacks (or not written as one), a fan named without an index, an
    /// index on an ordinary group, a fan's peer named instead of its element,
    /// a fan or a fan's buffer misspelt, every element (`[*]`) where one is
    /// needed. `(label, message, help)`; `None` otherwise.
    pub(super) fn fan_problem(
        &self,
        text: &str,
        outputs: bool,
    ) -> Option<(String, String, String)> {
        let mut parts = text.split('.');
        let (comp, group, buffer) = (parts.next()?, parts.next()?, parts.next()?);
        let c = self.comps.get(comp)?;
        let groups = if outputs { c.outputs } else { c.inputs };
        let Some((name, rest)) = group.split_once('[') else {
            return match groups.iter().find(|g| g.peer == group) {
                Some(g) if !g.peers.is_empty() => {
                    let len = g.peers.len();
                    Some((
                        "a fan, without an element".into(),
                        format!(
                            "link end `{text}` names fan `{group}` of `{comp}` without an element"
                        ),
                        format!(
                            "name one of its {len} elements: `{comp}.{group}[k].{buffer}` with k from 0 to {}",
                            len - 1
                        ),
                    ))
                }
                Some(_) => None,
                None => peer_of_fan(groups, comp, group, buffer, text),
            };
        };
        let index = rest.strip_suffix(']');
        let Some(g) = groups.iter().find(|g| g.peer == name) else {
            return misspelt_fan(groups, comp, name, text);
        };
        let len = g.peers.len();
        let every = index == Some("*");
        match index.and_then(fan_index) {
            _ if len == 0 => Some((
                "not a fan".into(),
                format!("link end `{text}` indexes group `{name}` of `{comp}`, which is not a fan"),
                format!("name its buffers `{comp}.{name}.{buffer}`; a group with `peers` is a fan"),
            )),
            Some(k) if k >= len => Some((
                format!("no element {k}"),
                format!(
                    "link end `{text}` names element {k} of fan `{name}` of `{comp}`, which has {len} element(s)"
                ),
                format!("an index below {len}, or one more peer in the fan's `peers`"),
            )),
            None if !every => Some((
                "not an index".into(),
                format!("link end `{text}` does not index fan `{name}` of `{comp}` with a number"),
                "write the index in decimal without leading zeros: `[0]`, `[12]` (or `[*]`, every element, in contracts and ROS 2 entries)".into(),
            )),
            _ if !g.buffers.iter().any(|b| b.name == buffer) => {
                let names = g.buffers.iter().map(|b| b.name.as_str());
                let guess = crate::names::did_you_mean(buffer, names.clone())
                    .map(|b| format!("did you mean `{comp}.{group}.{b}`? "))
                    .unwrap_or_default();
                Some((
                    "no such buffer".into(),
                    format!("`{text}` names no buffer `{buffer}` of fan `{name}` of `{comp}`"),
                    format!("{guess}its buffers: {}", names.collect::<Vec<_>>().join(", ")),
                ))
            }
            None => Some((
                "every element".into(),
                format!("`{text}` names every element of fan `{name}` of `{comp}`, where one element is needed"),
                format!(
                    "name one element, `{comp}.{name}[k].{buffer}` with k from 0 to {}: links, chains' hops and write intervals join one element; `[*]` is for contracts and ROS 2 entries",
                    len - 1
                ),
            )),
            Some(_) => None,
        }
    }

    // -----------------------------------------------------------------------
    // Deployments

    /// Each deployment: unique names, every component run or omitted exactly
    /// once, usable endpoints.
    pub(super) fn deployments(&mut self) {
        let spec = self.spec;
        let names = spec.deployments.iter().map(|x| x.name.as_str());
        self.unique("deployment", names_at(&[], "deployments", names));
        let mut all: Vec<&str> = self.comps.keys().copied().collect();
        all.sort_unstable();
        for (d, dep) in spec.deployments.iter().enumerate() {
            self.unique_hosts_and_processes(d, dep);
            let placed = self.placements(d, dep);
            self.endpoints(d, dep);
            let dpath = vec![F("deployments"), I(d)];
            for name in &all {
                if !placed.contains_key(name) {
                    self.push(
                        Finding::new(Code::DeployMissing, self.span(&join(&dpath, &[F("name")])), format!("`{name}` is not placed"), format!("deployment `{}` neither runs nor omits `{name}`", dep.name))
                            .help(format!("add `{name}` to a process's `runs`, or to `omit` if this deployment goes without it")),
                    );
                }
            }
        }
    }

    /// The hosts of deployment `d` have unique names, and so have its
    /// processes.
    fn unique_hosts_and_processes(&mut self, d: usize, dep: &'a Deployment) {
        let dpath = vec![F("deployments"), I(d)];
        let hosts = dep.hosts.iter().map(|x| x.name.as_str());
        self.unique("host", names_at(&dpath, "hosts", hosts));
        let processes = dep.hosts.iter().enumerate().flat_map(|(h, host)| {
            let processes = host.processes.iter().map(|x| x.name.as_str());
            names_at(&join(&dpath, &[F("hosts"), I(h)]), "processes", processes)
        });
        self.unique("process", processes);
    }

    /// Where deployment `d` places each component it runs or omits, reporting
    /// names that are no component and components placed twice.
    fn placements(&mut self, d: usize, dep: &'a Deployment) -> HashMap<&'a str, Path> {
        let dpath = vec![F("deployments"), I(d)];
        let mut placed: HashMap<&str, Path> = HashMap::new();
        for (h, host) in dep.hosts.iter().enumerate() {
            for (p, proc_) in host.processes.iter().enumerate() {
                for (k, name) in proc_.runs.iter().enumerate() {
                    self.place(
                        dep,
                        &mut placed,
                        name,
                        join(
                            &dpath,
                            &[F("hosts"), I(h), F("processes"), I(p), F("runs"), I(k)],
                        ),
                        "runs",
                    );
                }
            }
        }
        for (k, name) in dep.omit.iter().enumerate() {
            self.place(
                dep,
                &mut placed,
                name,
                join(&dpath, &[F("omit"), I(k)]),
                "omits",
            );
        }
        placed
    }

    /// Place component `name` (at `path`, which deployment `dep` `what`s: runs
    /// or omits), unless it is no component or is placed already.
    fn place(
        &mut self,
        dep: &Deployment,
        placed: &mut HashMap<&'a str, Path>,
        name: &'a str,
        path: Path,
        what: &str,
    ) {
        if !self.comps.contains_key(name) {
            let known = self.known_components();
            let guess = self.guess_component(name);
            self.push(
                Finding::new(
                    Code::UnknownComponent,
                    self.span(&path),
                    "no such component",
                    format!(
                        "deployment `{}` {what} `{name}`, which is not a component",
                        dep.name
                    ),
                )
                .help(format!("{guess}components: {known}")),
            );
            return;
        }
        if let Some(first) = placed.get(name) {
            let first = self.span(first);
            self.push(
                Finding::new(
                    Code::DeployTwice,
                    self.span(&path),
                    "placed again",
                    format!("deployment `{}` places `{name}` twice", dep.name),
                )
                .label(first, "first placed here")
                .help("a component runs in exactly one process, or is omitted"),
            );
        } else {
            placed.insert(name, path);
        }
    }

    /// Each process of deployment `d` listens on an endpoint Zenoh can use, and
    /// no two on the same one.
    fn endpoints(&mut self, d: usize, dep: &Deployment) {
        let mut seen: HashMap<String, Path> = HashMap::new();
        let mut k = 0;
        let endpoints = dep.processes();
        for (h, host) in dep.hosts.iter().enumerate() {
            for (p, proc_) in host.processes.iter().enumerate() {
                let endpoint = endpoints
                    .get(k)
                    .map(|(_, _, e)| e.clone())
                    .unwrap_or_default();
                k += 1;
                let field = if proc_.listen.is_some() {
                    "listen"
                } else {
                    "name"
                };
                let path = vec![
                    F("deployments"),
                    I(d),
                    F("hosts"),
                    I(h),
                    F("processes"),
                    I(p),
                    F(field),
                ];
                if let Err(why) = check_endpoint(&endpoint) {
                    self.push(
                        Finding::new(
                            Code::DeployEndpoint,
                            self.span(&path),
                            "not an endpoint",
                            format!(
                                "process `{}` of deployment `{}` listens on `{endpoint}`: {why}",
                                proc_.name, dep.name
                            ),
                        )
                        .help("write `tcp/<address>:<port>` (a secure deployment's links go over QUIC on the same address and port)"),
                    );
                    continue;
                }
                if let Some(first) = seen.get(&endpoint) {
                    let first = self.span(first);
                    self.push(
                        Finding::new(
                            Code::DeployEndpoint,
                            self.span(&path),
                            "endpoint taken",
                            format!(
                                "process `{}` of deployment `{}` listens on `{endpoint}`, as another process does",
                                proc_.name, dep.name
                            ),
                        )
                        .label(first, "first listens here")
                        .help("give each process its own `listen`, or its host an `address`"),
                    );
                } else {
                    seen.insert(endpoint, path);
                }
            }
        }
        if let Some(router) = &dep.router
            && let Err(why) = check_endpoint(router)
        {
            self.push(
                Finding::new(
                    Code::DeployEndpoint,
                    self.span(&[F("deployments"), I(d), F("router")]),
                    "not an endpoint",
                    format!("the router of deployment `{}`, `{router}`: {why}", dep.name),
                )
                .help("write `tcp/<address>:<port>`"),
            );
        }
    }

    /// What really feeds input `dotted` (buffer `buffer` of `component`'s group
    /// for `peer`): an existing output of the peer towards `component` (one not linked
    /// yet, of the same type, the same name first), or else the output to add.
    pub(super) fn feeding_help(
        &self,
        component: &str,
        peer: &str,
        buffer: &Buffer,
        dotted: &str,
        read_outputs: &HashSet<(String, String, String)>,
    ) -> String {
        let Some(p) = self.comps.get(peer) else {
            return format!("the group's peer `{peer}` is not a component; fix the peer first");
        };
        let Some(towards) = p.outputs.iter().find(|g| g.peer == component) else {
            return format!(
                "`{peer}` has no outputs towards `{component}`: add `(peer: \"{component}\", buffers: [(name: \"{}\", type: \"{}\")])` to its `outputs`, then link `(from: \"{peer}.{component}.{}\", to: \"{dotted}\")`",
                buffer.name, buffer.ty, buffer.name
            );
        };
        let same_type = |b: &&Buffer| normalize_type(&b.ty) == normalize_type(&buffer.ty);
        let mut candidates: Vec<&Buffer> = towards.buffers.iter().filter(same_type).collect();
        // Unlinked outputs first, then the one of the same name.
        candidates.sort_by_key(|b| {
            let linked =
                read_outputs.contains(&(peer.to_owned(), component.to_owned(), b.name.clone()));
            (linked, b.name != buffer.name)
        });
        match candidates.first() {
            Some(b) => format!(
                "link an output of the same type to it: `(from: \"{peer}.{component}.{}\", to: \"{dotted}\")`",
                b.name
            ),
            None => format!(
                "`{peer}` sends `{component}` no `{}`: add `(name: \"{}\", type: \"{}\")` to its outputs towards `{component}`, then link `(from: \"{peer}.{component}.{}\", to: \"{dotted}\")`",
                buffer.ty, buffer.name, buffer.ty, buffer.name
            ),
        }
    }
}

/// Whether `endpoint` is `<tcp|tls|quic>/<host>:<port>`, and why not.
fn check_endpoint(endpoint: &str) -> Result<(), String> {
    let Some((proto, rest)) = endpoint.split_once('/') else {
        return Err("no protocol (`tcp/`, `tls/` or `quic/`)".into());
    };
    if !matches!(proto, "tcp" | "tls" | "quic") {
        return Err(format!("protocol `{proto}` is not `tcp`, `tls` or `quic`"));
    }
    let Some((host, port)) = rest.rsplit_once(':') else {
        return Err("no `:<port>`".into());
    };
    if host.is_empty() {
        return Err("no host".into());
    }
    match port.parse::<u16>() {
        Ok(p) if p > 0 => Ok(()),
        _ => Err(format!("`{port}` is not a port (1-65535)")),
    }
}

/// The buffers that links read and write, gathered over every link.
#[derive(Default)]
struct Feeds {
    /// Per input `(component, group, buffer)`: the links that write it.
    writers: HashMap<(String, String, String), Vec<usize>>,
    /// The outputs `(component, group, buffer)` that some link reads.
    read_outputs: HashSet<(String, String, String)>,
}

/// One buffer of a component as the feed findings speak of it: the key under
/// which [`Feeds`] holds it, the name a link gives it, and where the spec
/// declares it.
struct BufferRef<'b> {
    component: &'b str,
    /// The component at the other end (a fan element's own peer).
    peer: String,
    buffer: &'b Buffer,
    /// `(component, group, buffer)`, as in [`Feeds`].
    key: (String, String, String),
    /// `component.group.buffer`, as a link's end names it.
    dotted: String,
    /// Where the spec names the buffer.
    path: Path,
}

impl<'b> BufferRef<'b> {
    /// Buffer `buffer` of `group`, or of its element `element` if it is a fan.
    fn new(
        component: &'b str,
        group: &'b Group,
        element: Option<usize>,
        buffer: &'b Buffer,
        path: Path,
    ) -> Self {
        let (peer, name) = match element.and_then(|k| Some((k, group.peers.get(k)?))) {
            Some((k, peer)) => (peer.clone(), format!("{}[{k}]", group.peer)),
            None => (group.peer.clone(), group.peer.clone()),
        };
        BufferRef {
            component,
            key: (component.to_owned(), peer.clone(), buffer.name.clone()),
            dotted: format!("{component}.{name}.{}", buffer.name),
            peer,
            buffer,
            path,
        }
    }
}

/// A fan's index as a link writes it (`3` in `c1[3]`): decimal, without
/// leading zeros, so that one element has one name.
fn fan_index(text: &str) -> Option<usize> {
    let canonical = !text.is_empty()
        && text.bytes().all(|b| b.is_ascii_digit())
        && (text == "0" || !text.starts_with('0'));
    canonical.then(|| text.parse().ok()).flatten()
}

/// `comp.peer.buffer` where `peer` is element `k` of one of `groups`' fans:
/// the element is named by its index.
fn peer_of_fan(
    groups: &[Group],
    comp: &str,
    peer: &str,
    buffer: &str,
    text: &str,
) -> Option<(String, String, String)> {
    groups.iter().find_map(|g| {
        let k = g.peers.iter().position(|p| p == peer)?;
        let fan = &g.peer;
        Some((
            format!("element {k} of fan `{fan}`"),
            format!("`{text}` names `{peer}`, which is element {k} of fan `{fan}` of `{comp}`"),
            format!("name the element by its index: `{comp}.{fan}[{k}].{buffer}`"),
        ))
    })
}

/// `comp.name[..].buffer` where `groups` have no group `name`: a guess among
/// their fans, if they have any.
fn misspelt_fan(
    groups: &[Group],
    comp: &str,
    name: &str,
    text: &str,
) -> Option<(String, String, String)> {
    let fans: Vec<&str> = groups
        .iter()
        .filter(|g| !g.peers.is_empty())
        .map(|g| g.peer.as_str())
        .collect();
    if fans.is_empty() {
        return None;
    }
    let guess = crate::names::did_you_mean(name, fans.iter().copied())
        .map(|f| format!("did you mean `{f}`? "))
        .unwrap_or_default();
    Some((
        "no such fan".into(),
        format!("`{text}` names fan `{name}`, which `{comp}` does not have on that side"),
        format!("{guess}fans of `{comp}` there: {}", fans.join(", ")),
    ))
}
