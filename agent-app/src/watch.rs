//! How a run ends and is judged: the rule the application states, the watcher
//! that reads what its probes report, and the summary every run ends with.

use std::fmt;
use std::time::Duration;

use agent_core::{ExecError, Time};

use crate::error::Status;

/// The layer's part of the rule that ends a run, beside the time limit and
/// the watcher's own ([`Watcher::ended`]).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub enum End {
    /// Only the time limit (or the watcher) ends the run.
    #[default]
    Limit,
    /// The run has ended when every one of these subsystems has halted
    /// (reached a final behaviour), wherever they run.
    Halted(Vec<String>),
}

impl End {
    /// [`End::Halted`] of `names`.
    pub fn halted<I: IntoIterator<Item = S>, S: Into<String>>(names: I) -> End {
        End::Halted(names.into_iter().map(Into::into).collect())
    }

    /// Whether the rule says more than the time limit.
    pub fn is_stated(&self) -> bool {
        !matches!(self, End::Limit)
    }
}

/// How a run ended.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Ended {
    /// By its rule: the subsystems named halted, or the watcher said so.
    Rule(String),
    /// At its time limit.
    Limit,
    /// Every node halted (nothing more can happen).
    AllHalted,
    /// Stopped before its end: a signal, a lost process, a spent restart
    /// budget (the reason).
    Stopped(String),
    /// An executor stopped on an error (the error).
    Failed(String),
}

impl Ended {
    /// The word of the summary line (`rule`, `limit`, `halted`, `stopped`,
    /// `failed`).
    pub fn word(&self) -> &'static str {
        match self {
            Ended::Rule(_) => "rule",
            Ended::Limit => "limit",
            Ended::AllHalted => "halted",
            Ended::Stopped(_) => "stopped",
            Ended::Failed(_) => "failed",
        }
    }
}

impl fmt::Display for Ended {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Ended::Rule(why) => write!(f, "ended by its rule: {why}"),
            Ended::Limit => f.write_str("reached its time limit"),
            Ended::AllHalted => f.write_str("every node halted"),
            Ended::Stopped(why) => write!(f, "stopped before its end: {why}"),
            Ended::Failed(why) => write!(f, "failed: {why}"),
        }
    }
}

/// Where a run ran.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Mode {
    /// The deterministic executor, in virtual time.
    Simulated,
    /// The real-time executor, in this process.
    RealTime,
    /// The processes of a deployment, started by `launch`.
    Launched {
        /// The deployment.
        deployment: String,
        /// Its processes.
        processes: usize,
        /// Restarts of crashed processes.
        restarts: u32,
    },
}

/// What every run ends with, whatever ended it.
#[derive(Clone, Debug)]
pub struct RunSummary {
    /// The spec's name.
    pub spec: String,
    /// Where it ran.
    pub mode: Mode,
    /// How it ended.
    pub ended: Ended,
    /// Whether the application stated an end rule beyond the time limit.
    pub rule_stated: bool,
    /// The last instant executed.
    pub last: Time,
    /// Wall-clock time of the run.
    pub wall: Duration,
    /// Errors the executors met (all of them, in every process).
    pub errors: u64,
    /// The first few, as text.
    pub first_errors: Vec<String>,
}

/// How many of a run's errors its summary names.
pub(crate) const FIRST_ERRORS: usize = 5;

/// The first [`FIRST_ERRORS`] of a run's `errors`, as text, for its summary.
pub(crate) fn first_errors<'e>(errors: impl IntoIterator<Item = &'e ExecError>) -> Vec<String> {
    errors
        .into_iter()
        .take(FIRST_ERRORS)
        .map(ToString::to_string)
        .collect()
}

impl RunSummary {
    /// The exit status of this run, judged `passed` or not: success only if
    /// it passed, its recording (if any) was finished and no stop cut it short.
    pub(crate) fn status(&self, passed: bool, recorded: bool) -> Status {
        let stopped = matches!(self.ended, Ended::Stopped(_));
        if passed && recorded && !stopped {
            Status::Success
        } else {
            Status::Failed
        }
    }

    /// Run time per wall-clock second.
    pub fn realtime_factor(&self) -> f64 {
        self.last.as_secs_f64() / self.wall.as_secs_f64().max(1e-9)
    }

    /// The layer's own judgement: the run ended by its rule (or, with no rule
    /// stated, at its limit or with every node halted) without an error.
    pub fn passed(&self) -> bool {
        let ended = match &self.ended {
            Ended::Rule(_) | Ended::AllHalted => true,
            Ended::Limit => !self.rule_stated,
            Ended::Stopped(_) | Ended::Failed(_) => false,
        };
        ended && self.errors == 0
    }

    /// The layer's verdict ([`RunSummary::passed`]) with its lines.
    pub fn verdict(&self) -> Verdict {
        let mut text = format!(
            "run of `{}` {} at t={:.3} s after {:.3} s of wall-clock time; {} executor errors\n",
            self.spec,
            self.ended,
            self.last.as_secs_f64(),
            self.wall.as_secs_f64(),
            self.errors
        );
        for e in &self.first_errors {
            text.push_str(&format!("error: {e}\n"));
        }
        if matches!(self.ended, Ended::Limit) && self.rule_stated {
            text.push_str("the run did not end by its rule within its time limit\n");
        }
        Verdict {
            passed: self.passed(),
            text,
            line: format!(
                "run={} ended={} sim_s={:.3} realtime_factor={:.1} executor_errors={}",
                self.spec,
                self.ended.word(),
                self.last.as_secs_f64(),
                self.realtime_factor(),
                self.errors
            ),
        }
    }
}

/// A run judged.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Verdict {
    /// Whether it succeeded (exit 0).
    pub passed: bool,
    /// The summary printed on standard output (lines, each ended by `\n`).
    pub text: String,
    /// The run's figures as one `key=value` line, printed last.
    pub line: String,
}

/// What reads a run as it goes: every report of the application's probes (in
/// a deployment, from every process), whether the run has reached its end,
/// a status line, and the judgement.
pub trait Watcher<M> {
    /// One report of a probe (or of [`Application::finished`](crate::Application::finished)).
    fn see(&mut self, seen: M);

    /// After each batch of reports: whether the run has reached its end
    /// (`finished`: the run is over and no report will follow).
    fn ended(&mut self, finished: bool) -> bool {
        let _ = finished;
        false
    }

    /// A status line for the progress display.
    fn status(&self) -> Option<String> {
        None
    }

    /// Judge the run. By default the layer's judgement ([`RunSummary::verdict`]).
    fn judge(&mut self, run: &RunSummary) -> Verdict {
        run.verdict()
    }
}

/// Counts of a run's parts added up. Each process of a deployment reports
/// its components' counters when it ends ([`Application::finished`](crate::Application::finished)),
/// and the watcher adds them: numbers saturating (they arrive over the
/// network), tuples element by element, lists joined.
///
/// ```
/// use agent_app::Tally;
///
/// let mut counts = (3u32, vec!["stop at 1 s"], 7u64);
/// counts.tally((1, vec!["stop at 2 s"], u64::MAX));
/// assert_eq!(counts, (4, vec!["stop at 1 s", "stop at 2 s"], u64::MAX));
/// ```
pub trait Tally {
    /// Add `other`'s counts to these.
    fn tally(&mut self, other: Self);
}

macro_rules! tally_numbers {
    ($($t:ty),*) => {$(
        impl Tally for $t {
            fn tally(&mut self, other: $t) {
                *self = self.saturating_add(other);
            }
        }
    )*};
}

tally_numbers!(u8, u16, u32, u64, u128, usize);

impl<T> Tally for Vec<T> {
    fn tally(&mut self, other: Vec<T>) {
        self.extend(other);
    }
}

impl<A: Tally, B: Tally> Tally for (A, B) {
    fn tally(&mut self, (a, b): (A, B)) {
        self.0.tally(a);
        self.1.tally(b);
    }
}

impl<A: Tally, B: Tally, C: Tally> Tally for (A, B, C) {
    fn tally(&mut self, (a, b, c): (A, B, C)) {
        self.0.tally(a);
        self.1.tally(b);
        self.2.tally(c);
    }
}

/// [`Tally`] for a struct that cannot derive it (defined where the framework
/// is not imported: an algorithm's report, say), its fields named: each is
/// tallied with the other's, as `#[derive(Tally)]` would.
///
/// ```
/// use agent_app::Tally;
///
/// #[derive(Debug, Default, PartialEq)]
/// pub struct SolverReport {
///     pub solves: u64,
///     pub failures: u32,
/// }
/// agent_app::tally_fields!(SolverReport: solves, failures);
///
/// let mut run = SolverReport { solves: 10, failures: 1 };
/// run.tally(SolverReport { solves: 5, failures: 0 });
/// assert_eq!(run, SolverReport { solves: 15, failures: 1 });
/// ```
#[macro_export]
macro_rules! tally_fields {
    ($ty:ty: $($field:ident),+ $(,)?) => {
        impl $crate::Tally for $ty {
            fn tally(&mut self, other: Self) {
                $($crate::Tally::tally(&mut self.$field, other.$field);)+
            }
        }
    };
}

/// Something to do every `period` of a run's time, as the run reports its
/// instants: a progress line every few seconds of simulated time, say. The
/// first is due one period after the start; each due instant moves the next
/// one period on (after a gap in the instants, each is due until the due
/// instants have caught up).
///
/// ```
/// use std::time::Duration;
/// use agent_app::Every;
/// use agent_core::Time;
///
/// let mut every = Every::new(Duration::from_secs(5));
/// let due: Vec<u64> = (0..=12)
///     .filter(|s| every.due(Time::from_nanos(s * 1_000_000_000)))
///     .collect();
/// assert_eq!(due, [5, 10]);
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Every {
    period_ns: u128,
    next_ns: u128,
}

impl Every {
    /// Every `period` (at least a nanosecond).
    pub fn new(period: Duration) -> Every {
        let period_ns = period.as_nanos().max(1);
        Every {
            period_ns,
            next_ns: period_ns,
        }
    }

    /// Whether the instant `t` has reached the next due one; if so, the next
    /// is a period later.
    pub fn due(&mut self, t: Time) -> bool {
        let due = u128::from(t.as_nanos()) >= self.next_ns;
        if due {
            self.next_ns += self.period_ns;
        }
        due
    }
}

/// A watcher that reads nothing and judges as the layer does.
#[derive(Clone, Copy, Debug, Default)]
pub struct Quiet;

impl<M> Watcher<M> for Quiet {
    fn see(&mut self, _: M) {}
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, Default, PartialEq)]
    struct Report {
        solves: u64,
        stops: Vec<&'static str>,
        pairs: (u8, u8),
    }
    crate::tally_fields!(Report: solves, stops, pairs);

    #[test]
    fn tally_fields_adds_each_field_named() {
        let mut a = Report {
            solves: u64::MAX - 1,
            stops: vec!["at 1 s"],
            pairs: (1, 2),
        };
        a.tally(Report {
            solves: 5,
            stops: vec!["at 2 s"],
            pairs: (250, 3),
        });
        let want = Report {
            solves: u64::MAX,
            stops: vec!["at 1 s", "at 2 s"],
            pairs: (251, 5),
        };
        assert_eq!(a, want);
    }

    #[test]
    fn every_is_due_once_per_period_reached() {
        let mut every = Every::new(Duration::from_millis(100));
        let ms = |k: u64| Time::from_nanos(k * 1_000_000);
        assert!(!every.due(ms(99)));
        assert!(every.due(ms(100)));
        assert!(!every.due(ms(150)));
        // After a jump past several periods, each instant is due until the
        // due instants have caught up (one period each).
        assert!(every.due(ms(450)));
        assert!(every.due(ms(451)));
        assert!(every.due(ms(452)));
        assert!(!every.due(ms(453)), "the next is at 500 ms");
        assert!(every.due(ms(500)));
        let mut zero = Every::new(Duration::ZERO);
        assert!(
            zero.due(Time::from_nanos(1)),
            "a zero period is a nanosecond"
        );
    }
}
