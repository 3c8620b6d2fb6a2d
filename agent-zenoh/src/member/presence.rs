//! How a member follows the others: their presence (the epoch each announced,
//! the inboxes told when one comes or is lost), the deployment's stop signal
//! and, for a launched process, its launcher.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};

use zenoh::Wait;
use zenoh::sample::SampleKind;

use super::Member;
use super::layout::Layout;

/// Who asked the deployment to stop, as the stop signal says (`None`: nobody yet).
pub(super) type StoppedBy = Arc<Mutex<Option<String>>>;

/// The other processes' presence as this process follows it: the epoch each
/// announced, the inboxes to tell when one comes or is lost, and who is lost.
#[derive(Clone)]
pub(super) struct Presence {
    /// The transport's inboxes, by receiving component.
    pub(super) senders: crate::transport::Senders,
    /// Who runs what: to tell the inboxes fed by a process that vanished.
    pub(super) runs: HashMap<String, Vec<String>>,
    /// The epoch each process announced with its presence: its values are
    /// the only ones its inboxes here take (a new epoch is its restart).
    pub(super) epochs: Arc<Mutex<HashMap<String, u64>>>,
    /// Whether a stop was asked: processes that end after it are not lost.
    pub(super) stop: Arc<AtomicBool>,
    /// The processes lost.
    pub(super) gone: Arc<Mutex<Vec<String>>>,
}

impl Presence {
    /// Nobody seen yet, nor lost, and no stop asked; `senders` are the
    /// transport's inboxes.
    pub(super) fn new(layout: &Layout, senders: crate::transport::Senders) -> Presence {
        Presence {
            senders,
            runs: layout
                .processes
                .iter()
                .map(|(p, _, r)| (p.clone(), r.clone()))
                .collect(),
            epochs: Arc::new(Mutex::new(HashMap::new())),
            stop: Arc::new(AtomicBool::new(false)),
            gone: Arc::new(Mutex::new(Vec::new())),
        }
    }

    /// Follow the processes' presence tokens (`process/<name>/<epoch>`, those
    /// already there included) for as long as the subscriber lives.
    pub(super) fn watch(
        self,
        session: &zenoh::Session,
        layout: &Layout,
    ) -> Result<zenoh::pubsub::Subscriber<()>, zenoh::Error> {
        let process_prefix = layout.rt_key("process/");
        session
            .liveliness()
            .declare_subscriber(layout.rt_key("process/*/*"))
            .history(true)
            .callback(move |sample| {
                let key = sample.key_expr().as_str();
                let Some((name, epoch)) = key
                    .strip_prefix(process_prefix.as_str())
                    .and_then(|rest| rest.split_once('/'))
                    .and_then(|(n, e)| Some((n, e.parse::<u64>().ok()?)))
                else {
                    return;
                };
                if sample.kind() == SampleKind::Put {
                    self.came(name, epoch);
                } else {
                    self.went(name);
                }
            })
            .wait()
    }

    /// Process `name` is present with `epoch`: the inboxes it feeds take its
    /// values of that epoch.
    fn came(&self, name: &str, epoch: u64) {
        self.epochs
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .insert(name.to_owned(), epoch);
        let senders = self.senders.lock().unwrap_or_else(PoisonError::into_inner);
        for component in self.runs.get(name).into_iter().flatten() {
            for inbox in senders.get(component).into_iter().flatten() {
                inbox.expect(epoch);
            }
        }
    }

    /// Process `name` is gone: lost, unless a stop was asked.
    fn went(&self, name: &str) {
        // Processes that end after a stop was asked are not lost.
        if self.stop.load(Ordering::Relaxed) {
            return;
        }
        // A process that leaves because the deployment was asked to stop may
        // be seen to go before the stop itself arrives here (they travel
        // different ways): judge it a moment later.
        let (presence, name) = (self.clone(), name.to_owned());
        std::thread::spawn(move || {
            std::thread::sleep(Member::STOP_SKEW);
            if presence.stop.load(Ordering::Relaxed) {
                return;
            }
            presence.lost(name);
        });
    }

    /// Tell the inboxes that process `name` feeds that it is lost, and count
    /// it among the lost.
    fn lost(&self, name: String) {
        let senders = self.senders.lock().unwrap_or_else(PoisonError::into_inner);
        for component in self.runs.get(&name).into_iter().flatten() {
            for inbox in senders.get(component).into_iter().flatten() {
                inbox.peer_lost(&name);
            }
        }
        self.gone
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push(name);
    }
}

/// Follow the deployment's stop signal: it sets `stop`; the first sender's
/// name is kept.
pub(super) fn watch_stop(
    session: &zenoh::Session,
    layout: &Layout,
    stop: &Arc<AtomicBool>,
) -> Result<(zenoh::pubsub::Subscriber<()>, StoppedBy), zenoh::Error> {
    let stop_flag = stop.clone();
    let stopped_by = Arc::new(Mutex::new(None));
    let by = stopped_by.clone();
    let subscriber = session
        .declare_subscriber(layout.rt_key("stop"))
        .callback(move |sample| {
            // The sender names itself (at most a line of it is kept).
            let who: String = String::from_utf8_lossy(&sample.payload().to_bytes())
                .chars()
                .take(200)
                .filter(|c| !c.is_control())
                .collect();
            by.lock()
                .unwrap_or_else(PoisonError::into_inner)
                .get_or_insert(who);
            stop_flag.store(true, Ordering::Relaxed);
        })
        .wait()?;
    Ok((subscriber, stopped_by))
}

/// A launched process ends with its launcher: when the launcher's presence
/// goes (killed, its host lost), the flag returned and `stop` are set. No
/// subscriber for a process started by hand.
pub(super) fn watch_launcher(
    session: &zenoh::Session,
    layout: &Layout,
    launched: bool,
    stop: &Arc<AtomicBool>,
) -> Result<(Option<zenoh::pubsub::Subscriber<()>>, Arc<AtomicBool>), zenoh::Error> {
    let launcher_gone = Arc::new(AtomicBool::new(false));
    if !launched {
        return Ok((None, launcher_gone));
    }
    let (gone_flag, stop_flag) = (launcher_gone.clone(), stop.clone());
    let subscriber = session
        .liveliness()
        .declare_subscriber(layout.rt_key("launcher"))
        .callback(move |sample| {
            if sample.kind() == SampleKind::Delete {
                gone_flag.store(true, Ordering::Relaxed);
                stop_flag.store(true, Ordering::Relaxed);
            }
        })
        .wait()?;
    Ok((Some(subscriber), launcher_gone))
}
