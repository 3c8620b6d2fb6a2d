//! Links between processes: the halves of a link whose two ends run in different
//! processes (or hosts), over any byte transport that implements [`Transport`]
//! (the `agent-zenoh` crate implements it over Eclipse Zenoh).
//!
//! The node code does not change: a remote half is one more kind of the
//! real-time executor's link halves, behind the same ports.
//!
//! # Messages
//!
//! Each value travels as one message: a 41-byte header, then the value in
//! postcard's compact encoding.
//!
//! | bytes | field |
//! |---|---|
//! | 0 | wire version (1) |
//! | 1..9 | the payload type's [`fingerprint`] |
//! | 9..17 | the sender's epoch (a new one each time the sending process starts) |
//! | 17..25 | sequence number, from 1, per sender and epoch |
//! | 25..33 | the sender's iteration |
//! | 33..41 | the sender's instant, in ns |
//!
//! The receiver ([`Inbox`]) checks the fingerprint (a process built from
//! different code is refused: [`RemoteProblem::Fingerprint`]), and on a queue link
//! the sequence: a gap is [`RemoteProblem::Gap`], never a silent loss; on
//! every link a repeat (or a value numbered before one taken) is refused
//! ([`RemoteProblem::Duplicate`]). A new epoch is a restarted
//! sender, numbering again from 1; a first value numbered later (values sent
//! before this receiver listened, or while its process was down) is a gap,
//! except for a receiver that joined a running deployment late (its process
//! restarted): the values its sender sent before were not for it, and its
//! first value from that sender starts the count ([`Inbox::start`]).
//! Sample links keep the latest value; queue links keep every value in order, up
//! to the link's bound (more is [`RemoteProblem::Overflow`]). Problems reach the
//! receiving node's executor at its next read, as [`LinkError::Remote`](crate::LinkError::Remote), and go
//! through its error policy like any other error.
//!
//! No single message blocks or poisons a link: a value from a second sender
//! ([`RemoteProblem::Intruder`]: of another epoch than the one the sending
//! process announced, [`Inbox::expect`]; without an announcement, a new epoch is a
//! restart only once the sender was seen to go, [`Inbox::peer_lost`]), a value
//! stamped more than [`MAX_LEAD`] ahead of the reader's instant
//! ([`RemoteProblem::Implausible`], which would otherwise hold every value
//! behind it in a queue), and a body with bytes after the value are refused.
//! Every refused message is counted in the link's [`LinkStats::refused`], though
//! only the first few wait to be reported.
//!
//! [`LinkStats::refused`]: crate::LinkStats::refused

use std::collections::VecDeque;
use std::fmt;
use std::hash::Hasher;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex, PoisonError};

use super::shape::Fnv;
pub use super::shape::{TypeShape, fingerprint, reflect};
use crate::buffer::{In, Payload};
use crate::error::RemoteProblem;
use crate::kinds::Policy;
use crate::time::{Stamp, Time};
use crate::trace::{LinkInfo, SystemInfo};

use super::reads::{Held, ReadGrid};
use super::stats::SharedStats;

/// How far ahead of the reading activation's instant a value's stamp may be:
/// the processes of a deployment share instant zero and run on the same clock
/// (across hosts, as well as their clocks agree), so a sender is ahead of a
/// reader by a period or a clock's error, never by seconds.
pub const MAX_LEAD: std::time::Duration = std::time::Duration::from_secs(5);

/// The wire format's version, first byte of every message.
pub const WIRE_VERSION: u8 = 1;
/// The header's length in bytes.
pub const HEADER_LEN: usize = 41;

/// Why a transport could not do what it was asked.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct TransportError(pub String);

/// Sends the messages of one output buffer (one key).
pub trait Publisher: Send {
    /// Send one message. Must not block for long: a sample link's publisher may
    /// drop under congestion (the receiver keeps the latest anyway); a queue
    /// link's publisher must not drop (reliable delivery), and reports what it
    /// cannot send.
    fn put(&mut self, message: &[u8]) -> Result<(), TransportError>;
}

/// A byte transport between processes: publishers and subscribers on keys.
pub trait Transport: Send {
    /// A publisher on `key` for a link with `policy` (`Queue`: reliable and
    /// lossless; `Sample`: the latest value matters).
    fn publisher(
        &mut self,
        key: &str,
        policy: Policy,
    ) -> Result<Box<dyn Publisher>, TransportError>;

    /// Subscribe to `key`: call [`Inbox::deliver`] with each message received,
    /// from any thread. The returned value keeps the subscription alive; dropping
    /// it ends the subscription.
    fn subscribe(
        &mut self,
        key: &str,
        inbox: Arc<Inbox>,
    ) -> Result<Box<dyn std::any::Any + Send>, TransportError>;
}

/// The key of the values sent by `link`'s output buffer:
/// `prefix/agent/component/group/buffer` (the port's dots become slashes). One
/// output has one key whichever the number of inputs it feeds.
pub fn link_key(prefix: &str, info: &SystemInfo, link: &LinkInfo) -> String {
    let node = &info.nodes[link.from];
    let mut key = String::with_capacity(prefix.len() + 48);
    if !prefix.is_empty() {
        key.push_str(prefix.trim_end_matches('/'));
        key.push('/');
    }
    key.push_str(&node.agent);
    key.push('/');
    key.push_str(&node.name);
    for part in link.from_port.split('.') {
        key.push('/');
        key.push_str(part);
    }
    key
}

/// A message's header, decoded (see the module's table): what a link carries
/// between processes, and what a recording keeps with each value.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WireHeader {
    /// The payload type's [`fingerprint`].
    pub fingerprint: u64,
    /// The sender's epoch.
    pub epoch: u64,
    /// The sequence number, from 1, per sender and epoch.
    pub seq: u64,
    /// The sender's iteration and instant.
    pub stamp: Stamp,
}

impl WireHeader {
    /// Write the header into `out` (cleared first); the value's postcard
    /// encoding follows it.
    pub fn write(&self, out: &mut Vec<u8>) {
        write_header(out, self);
    }

    /// Split a message into its header and the value's postcard encoding.
    pub fn read(message: &[u8]) -> Result<(WireHeader, &[u8]), RemoteProblem> {
        let header = read_header(message)?;
        Ok((header, &message[HEADER_LEN..]))
    }
}

type Header = WireHeader;

fn write_header(out: &mut Vec<u8>, h: &Header) {
    out.clear();
    out.push(WIRE_VERSION);
    for v in [
        h.fingerprint,
        h.epoch,
        h.seq,
        h.stamp.iteration,
        h.stamp.time.as_nanos(),
    ] {
        out.extend_from_slice(&v.to_le_bytes());
    }
}

fn read_header(message: &[u8]) -> Result<Header, RemoteProblem> {
    let word = |k: usize| -> Option<u64> {
        let bytes = message.get(1 + 8 * k..9 + 8 * k)?;
        Some(u64::from_le_bytes(bytes.try_into().ok()?))
    };
    match message.first() {
        Some(&WIRE_VERSION) => {}
        Some(&v) => {
            return Err(RemoteProblem::Decode(format!(
                "wire version {v}, this build speaks {WIRE_VERSION}"
            )));
        }
        None => return Err(RemoteProblem::Decode("an empty message".into())),
    }
    match (word(0), word(1), word(2), word(3), word(4)) {
        (Some(fingerprint), Some(epoch), Some(seq), Some(iteration), Some(ns)) => Ok(Header {
            fingerprint,
            epoch,
            seq,
            stamp: Stamp::new(iteration, Time::from_nanos(ns)),
        }),
        _ => Err(RemoteProblem::Decode(format!(
            "a message of {} bytes, shorter than the {HEADER_LEN}-byte header",
            message.len()
        ))),
    }
}

/// A new epoch for a sending process: different at each start (time and
/// process id mixed), so that receivers tell a restart from a gap.
pub fn new_epoch() -> u64 {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64);
    let mut h = Fnv::default();
    h.write(&nanos.to_le_bytes());
    h.write(&std::process::id().to_le_bytes());
    h.finish().max(1)
}

// ---------------------------------------------------------------------------
// Sending

/// The sending half of a link to another process.
///
/// A sample link whose readers elsewhere read less often than its writer
/// writes has a [`ReadGrid`]: a value is held, encoded, until the writer's
/// last activation before the read that sees it, and published then; a value
/// written over while held is counted as overwritten, as in-process
/// ([`super::reads`]).
pub(crate) struct RemoteTx {
    /// `None` when another link of the same output publishes on the key (one
    /// publication reaches every subscriber).
    publisher: Option<Box<dyn Publisher>>,
    key: Arc<str>,
    header: Header,
    buf: Vec<u8>,
    stats: Arc<SharedStats>,
    /// When the readers read, and the value held for them (sample links
    /// thinned to their readers' instants).
    reads: Option<(ReadGrid, Held)>,
}

impl RemoteTx {
    pub(crate) fn key(&self) -> &Arc<str> {
        &self.key
    }

    pub(crate) fn new(
        publisher: Option<Box<dyn Publisher>>,
        key: Arc<str>,
        fingerprint: u64,
        epoch: u64,
        stats: Arc<SharedStats>,
    ) -> Self {
        RemoteTx {
            publisher,
            key,
            header: Header {
                fingerprint,
                epoch,
                seq: 0,
                stamp: Stamp::new(0, Time::ZERO),
            },
            buf: Vec::with_capacity(256),
            stats,
            reads: None,
        }
    }

    /// Publish only the values read at `grid`'s instants (a sample link's
    /// publisher; `None`: every value).
    pub(crate) fn at_reads(mut self, grid: Option<ReadGrid>) -> Self {
        self.reads = grid.map(|g| (g, Held::default()));
        self
    }

    /// Encode and publish `value` (or hold it for the read that sees it).
    pub(crate) fn put<T: Payload>(&mut self, value: &T, stamp: Stamp) -> Result<(), RemoteProblem> {
        if self.publisher.is_none() {
            self.stats.sent.fetch_add(1, Ordering::Relaxed);
            return Ok(());
        }
        let Some((grid, held)) = self.reads.as_ref() else {
            self.encode(value, stamp)?;
            self.publish()?;
            self.stats.sent.fetch_add(1, Ordering::Relaxed);
            return Ok(());
        };
        let (read, pending) = (grid.next_read(stamp.time), held.read);
        // A held value whose read is past (the writer's activations before
        // it were skipped) goes first, late; one whose read is still ahead
        // is written over before any reader sees it.
        let late = match pending {
            Some(r) if r <= stamp.time.as_nanos() => self.release(),
            Some(_) => {
                self.stats.overwritten.fetch_add(1, Ordering::Relaxed);
                Ok(())
            }
            None => Ok(()),
        };
        self.encode(value, stamp)?;
        if let Some((_, held)) = self.reads.as_mut() {
            std::mem::swap(&mut held.message, &mut self.buf);
            held.read = Some(read);
        }
        self.stats.sent.fetch_add(1, Ordering::Relaxed);
        late.and(self.idle(stamp.time))
    }

    /// The writer's activation at `now` (with or without a write): the held
    /// value is published if no later activation comes before its read.
    pub(crate) fn idle(&mut self, now: Time) -> Result<(), RemoteProblem> {
        match &self.reads {
            Some((grid, Held { read: Some(r), .. })) if grid.last_before(now, *r) => self.release(),
            _ => Ok(()),
        }
    }

    /// Publish the held value now, if there is one (the writer halts).
    pub(crate) fn flush(&mut self) -> Result<(), RemoteProblem> {
        self.release()
    }

    /// Publish the held value, if there is one.
    fn release(&mut self) -> Result<(), RemoteProblem> {
        let Some((_, held)) = self.reads.as_mut() else {
            return Ok(());
        };
        if held.read.take().is_none() {
            return Ok(());
        }
        std::mem::swap(&mut held.message, &mut self.buf);
        self.publish()
    }

    /// The message of `value` into `buf`, numbered after the last published.
    fn encode<T: Payload>(&mut self, value: &T, stamp: Stamp) -> Result<(), RemoteProblem> {
        let header = Header {
            seq: self.header.seq + 1,
            stamp,
            ..self.header
        };
        let mut buf = std::mem::take(&mut self.buf);
        write_header(&mut buf, &header);
        match postcard::to_extend(value, buf) {
            Ok(buf) => {
                self.buf = buf;
                Ok(())
            }
            Err(e) => Err(RemoteProblem::Encode(e.to_string())),
        }
    }

    /// Publish the message in `buf` (numbered when it was encoded).
    fn publish(&mut self) -> Result<(), RemoteProblem> {
        let Some(publisher) = self.publisher.as_mut() else {
            return Ok(());
        };
        self.header.seq += 1;
        publisher
            .put(&self.buf)
            .map_err(|e| RemoteProblem::Transport(format!("publishing on `{}`: {e}", self.key)))
    }
}

impl Drop for RemoteTx {
    /// The value held when the writer's run ends is published: a reader that
    /// runs on takes it at its next read, as it would in-process.
    fn drop(&mut self) {
        // Nobody is left to tell of a failure; the receiver sees no value.
        let _ = self.release();
    }
}

// ---------------------------------------------------------------------------
// Receiving

/// Where a transport delivers the messages of one link; the receiving node's
/// thread takes them at its reads.
pub struct Inbox {
    key: Arc<str>,
    fingerprint: u64,
    type_name: &'static str,
    policy: Policy,
    state: Mutex<InboxState>,
    stats: Arc<SharedStats>,
}

#[derive(Default)]
struct InboxState {
    values: VecDeque<(Stamp, Vec<u8>)>,
    problems: VecDeque<RemoteProblem>,
    /// The sender's epoch and the next sequence number expected from it.
    epoch: u64,
    next: u64,
    /// Message buffers given back by the reader, for the next deliveries.
    spare: Vec<Vec<u8>>,
    /// Restarts of the sender seen (a new epoch after the first).
    restarts: u64,
    /// Problems met, reported or not (at most `MAX_PROBLEMS` wait at once).
    problem_count: u64,
    /// Whether the receiving run has started ([`Inbox::start`]); until then a
    /// gap before the first value is held in `first_gap`.
    started: bool,
    /// The receiving run joined a running deployment late.
    late: bool,
    /// Whether a value from any sender was seen.
    heard: bool,
    first_gap: Option<RemoteProblem>,
    /// The sender was seen to go (its process left the deployment): a new
    /// epoch is its restart.
    sender_gone: bool,
    /// The epoch the sending process announced ([`Inbox::expect`]): the
    /// only one whose values are taken, once known.
    expected: Option<u64>,
    /// The instant of the reader's last read: a value stamped before it
    /// arrives late.
    last_read: Option<Time>,
}

impl fmt::Debug for Inbox {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Inbox")
            .field("key", &self.key)
            .field("policy", &self.policy)
            .finish()
    }
}

/// At most this many problems wait in an inbox; more are counted only
/// ([`Inbox::problem_count`]): a flood of refused values must not grow memory.
const MAX_PROBLEMS: usize = 16;

impl Inbox {
    pub(crate) fn new(
        key: Arc<str>,
        fingerprint: u64,
        type_name: &'static str,
        policy: Policy,
        stats: Arc<SharedStats>,
    ) -> Self {
        Inbox {
            key,
            fingerprint,
            type_name,
            policy,
            state: Mutex::new(InboxState {
                started: true,
                ..InboxState::default()
            }),
            stats,
        }
    }

    /// Hold the judgement of the first value until [`Inbox::start`]: made by
    /// a run that subscribes before it knows whether it joins late.
    pub(crate) fn defer_start(&self) {
        self.lock().started = false;
    }

    /// The receiving run starts; `late`: it joined a running deployment (its
    /// process restarted), so the first value from a sender starts the count
    /// of its numbering instead of revealing a gap (the values sent before
    /// were not for this receiver).
    pub fn start(&self, late: bool) {
        let mut state = self.lock();
        state.started = true;
        state.late = late;
        if let Some(gap) = state.first_gap.take()
            && !late
        {
            Self::problem(&mut state, gap);
        }
    }

    /// The key this inbox listens to.
    pub fn key(&self) -> &str {
        &self.key
    }

    pub(crate) fn key_arc(&self) -> Arc<str> {
        self.key.clone()
    }

    /// The fingerprint of the payload type its values must carry
    /// ([`fingerprint`]): what a feeder from outside the system writes in
    /// each message's header.
    pub fn fingerprint(&self) -> u64 {
        self.fingerprint
    }

    /// The counters of the values this inbox took in: delivered to the
    /// reader, refused, overwritten (sample), overflowed (queue).
    pub fn stats(&self) -> crate::LinkStats {
        self.stats.snapshot()
    }

    /// The link's policy.
    pub fn policy(&self) -> Policy {
        self.policy
    }

    /// How many times the sender restarted (a new epoch) while this inbox listened.
    pub fn restarts(&self) -> u64 {
        self.lock().restarts
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, InboxState> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }

    fn problem(state: &mut InboxState, p: RemoteProblem) {
        state.problem_count += 1;
        if state.problems.len() < MAX_PROBLEMS {
            state.problems.push_back(p);
        }
    }

    /// A message refused: counted in the link's statistics, and reported.
    fn refuse(&self, state: &mut InboxState, p: RemoteProblem) {
        self.stats.refused.fetch_add(1, Ordering::Relaxed);
        Self::problem(state, p);
    }

    /// Every problem this inbox met (values refused, gaps, lost peers),
    /// including those beyond the few that wait to be reported at the reads.
    pub fn problem_count(&self) -> u64 {
        self.lock().problem_count
    }

    /// A message arrived (called by the transport, from any thread).
    pub fn deliver(&self, message: &[u8]) {
        let mut state = self.lock();
        let header = match read_header(message) {
            Ok(h) => h,
            Err(p) => return self.refuse(&mut state, p),
        };
        if header.fingerprint != self.fingerprint {
            return self.refuse(
                &mut state,
                RemoteProblem::Fingerprint {
                    expected: self.fingerprint,
                    got: header.fingerprint,
                    type_name: self.type_name,
                },
            );
        }
        if header.epoch != state.epoch {
            // The sending process announced its epoch: values of any other
            // are not its own. Without an announcement, a new epoch is the
            // sender's restart once it was seen to go; while it runs, another
            // sender on its key is not its own.
            let legitimate = match state.expected {
                Some(e) => e == header.epoch,
                None => state.epoch == 0 || state.sender_gone,
            };
            if !legitimate {
                let current = state.epoch;
                return self.refuse(
                    &mut state,
                    RemoteProblem::Intruder {
                        current,
                        got: header.epoch,
                    },
                );
            }
            if state.epoch != 0 {
                state.restarts += 1;
            }
            state.sender_gone = false;
            state.epoch = header.epoch;
            // A sender's numbering starts at 1: a first value numbered later on
            // a queue link means values sent before this inbox listened (or
            // while its process was down) were lost, and that is reported.
            state.next = 1;
        }
        let first = !std::mem::replace(&mut state.heard, true);
        // A value numbered before one already taken is a repeat (a message
        // replayed by someone who saw it) or out of order, on any link: on a
        // sample link it would put an old value back as the latest.
        if header.seq < state.next {
            let (expected, got) = (state.next, header.seq);
            return self.refuse(&mut state, RemoteProblem::Duplicate { expected, got });
        }
        // A gap matters on a queue (a sample keeps only the latest anyway).
        if matches!(self.policy, Policy::Queue { .. }) && header.seq != state.next {
            let (expected, got) = (state.next, header.seq);
            let gap = RemoteProblem::Gap { expected, got };
            match (first, state.started, state.late) {
                // A late joiner's first value: nothing was lost for it.
                (true, true, true) => {}
                (true, false, _) => state.first_gap = Some(gap),
                _ => Self::problem(&mut state, gap),
            }
        }
        state.next = header.seq.wrapping_add(1);
        if state.last_read.is_some_and(|read| header.stamp.time < read) {
            self.stats.late.fetch_add(1, Ordering::Relaxed);
        }
        let mut body = state.spare.pop().unwrap_or_default();
        body.clear();
        body.extend_from_slice(&message[HEADER_LEN..]);
        match self.policy {
            Policy::Sample => {
                if let Some((_, old)) = state.values.pop_front() {
                    self.stats.overwritten.fetch_add(1, Ordering::Relaxed);
                    state.spare.push(old);
                }
                state.values.push_back((header.stamp, body));
            }
            Policy::Queue { bound } => {
                if state.values.len() >= bound.max(1) {
                    self.stats.overflowed.fetch_add(1, Ordering::Relaxed);
                    state.spare.push(body);
                    self.refuse(&mut state, RemoteProblem::Overflow { bound });
                } else {
                    state.values.push_back((header.stamp, body));
                    self.stats
                        .max_pending
                        .fetch_max(state.values.len(), Ordering::Relaxed);
                }
            }
        }
    }

    /// The sending process announced (or, restarted, announced again) the
    /// epoch its values carry: values of any other epoch are refused as
    /// another sender's ([`RemoteProblem::Intruder`]), and this one's are
    /// taken, a restart if the link heard another before.
    pub fn expect(&self, epoch: u64) {
        self.lock().expected = Some(epoch);
    }

    /// The sending process is gone (called by the transport or the runtime
    /// watching the processes).
    pub fn peer_lost(&self, process: &str) {
        let mut state = self.lock();
        state.sender_gone = true;
        Self::problem(
            &mut state,
            RemoteProblem::PeerLost {
                process: process.to_owned(),
            },
        );
    }

    /// The reader's side for an activation of instant `now`: the next value
    /// stamped at or before `now` (decoded into `x`; a later one waits, as on a
    /// link between threads) or the next problem.
    pub(crate) fn take_into<T: Payload>(
        &self,
        x: &mut In<T>,
        now: Time,
    ) -> Result<(), RemoteProblem> {
        let mut state = self.lock();
        if now != Time::NEVER {
            state.last_read = Some(now);
        }
        if let Some(p) = state.problems.pop_front() {
            x.age();
            return Err(p);
        }
        // A value stamped implausibly far ahead would hold every value behind
        // it: refused.
        let lead = u64::try_from(MAX_LEAD.as_nanos()).unwrap_or(u64::MAX);
        if let Some((stamp, _)) = state.values.front()
            && stamp.time.as_nanos() > now.as_nanos().saturating_add(lead)
        {
            let stamp = stamp.time;
            if let Some((_, body)) = state.values.pop_front() {
                state.spare.push(body);
            }
            self.stats.refused.fetch_add(1, Ordering::Relaxed);
            state.problem_count += 1;
            x.age();
            return Err(RemoteProblem::Implausible {
                stamp,
                now,
                lead: MAX_LEAD.as_secs(),
            });
        }
        if state
            .values
            .front()
            .is_none_or(|(stamp, _)| stamp.time > now)
        {
            x.age();
            return Ok(());
        }
        let Some((stamp, body)) = state.values.pop_front() else {
            x.age();
            return Ok(());
        };
        drop(state);
        // The whole body is the value: bytes after it are not a value of
        // this link (a value read from the start of a larger body).
        let decoded = match postcard::take_from_bytes::<T>(&body) {
            Ok((v, [])) => Ok(v),
            Ok((_, rest)) => Err(format!(
                "{} bytes after the value, of a body of {}",
                rest.len(),
                body.len()
            )),
            Err(e) => Err(e.to_string()),
        };
        let mut state = self.lock();
        state.spare.push(body);
        match decoded {
            Ok(v) => {
                drop(state);
                x.swap_in(&mut Some(v), stamp);
                self.stats.delivered.fetch_add(1, Ordering::Relaxed);
                Ok(())
            }
            Err(e) => {
                self.stats.refused.fetch_add(1, Ordering::Relaxed);
                state.problem_count += 1;
                x.age();
                Err(RemoteProblem::Decode(format!(
                    "a `{}` that does not decode: {e}",
                    self.type_name
                )))
            }
        }
    }
}

/// The receiving half of a link from another process.
pub(crate) struct RemoteRx {
    pub(crate) inbox: Arc<Inbox>,
}

// Beside this file, not in a folder of its own: agent-core's module-graph
// test reads one folder level per top-level module.
#[cfg(test)]
#[path = "remote_tests.rs"]
mod tests;
