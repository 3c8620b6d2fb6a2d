//! Behaviours: an elementary action repeated while or until a terminal condition
//! (Algorithms 2 and 3 of the paper).

use std::borrow::Cow;
use std::fmt;

use crate::subsystem::Subsystem;
use crate::transition::Action;

/// The two behaviour patterns of the paper.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum BehaviourKind {
    /// Algorithm 2: `while f^τ = false do A`. The terminal condition is tested before
    /// every iteration, including the first, so the action may run zero times.
    While,
    /// Algorithm 3: `repeat A until f^τ = true`. The action runs at least once; the
    /// condition is tested after each iteration (on the inputs read at its end).
    Repeat,
}

impl fmt::Display for BehaviourKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            BehaviourKind::While => "while",
            BehaviourKind::Repeat => "repeat",
        })
    }
}

impl BehaviourKind {
    /// Whether the terminal condition is tested now: always for `While`; for
    /// `Repeat` only once at least one action of this activation of the behaviour ran.
    #[inline]
    pub fn tests_terminal(self, actions_done: bool) -> bool {
        match self {
            BehaviourKind::While => true,
            BehaviourKind::Repeat => actions_done,
        }
    }
}

/// A behaviour `B_{j,m}(f_{j,m}, f^τ_{j,m})`: a named loop of one elementary action
/// with a terminal condition.
///
/// The terminal condition is a Boolean expression over the FSM's named predicates
/// (for instance `"plan_done && !ready"`, or `"false"` for a behaviour that never
/// ends); it is resolved when the FSM is built.
pub struct Behaviour<S: Subsystem> {
    pub(crate) name: Cow<'static, str>,
    pub(crate) kind: BehaviourKind,
    pub(crate) action: Action<S>,
    pub(crate) terminal: Cow<'static, str>,
}

impl<S: Subsystem> fmt::Debug for Behaviour<S> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Behaviour")
            .field("name", &self.name)
            .field("kind", &self.kind)
            .field("action", &self.action)
            .field("terminal", &self.terminal)
            .finish()
    }
}

impl<S: Subsystem> Behaviour<S> {
    /// A behaviour of either kind.
    pub fn new(
        name: impl Into<Cow<'static, str>>,
        kind: BehaviourKind,
        action: Action<S>,
        terminal: impl Into<Cow<'static, str>>,
    ) -> Self {
        Behaviour {
            name: name.into(),
            kind,
            action,
            terminal: terminal.into(),
        }
    }

    /// A while-type behaviour (Algorithm 2): `while !terminal { action }`.
    pub fn while_loop(
        name: impl Into<Cow<'static, str>>,
        action: Action<S>,
        terminal: impl Into<Cow<'static, str>>,
    ) -> Self {
        Self::new(name, BehaviourKind::While, action, terminal)
    }

    /// A repeat-type behaviour (Algorithm 3): `repeat { action } until terminal`.
    pub fn repeat_loop(
        name: impl Into<Cow<'static, str>>,
        action: Action<S>,
        terminal: impl Into<Cow<'static, str>>,
    ) -> Self {
        Self::new(name, BehaviourKind::Repeat, action, terminal)
    }

    /// The behaviour's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// While- or repeat-type.
    pub fn kind(&self) -> BehaviourKind {
        self.kind
    }

    /// The elementary action.
    pub fn action(&self) -> &Action<S> {
        &self.action
    }

    /// The terminal condition as written.
    pub fn terminal(&self) -> &str {
        &self.terminal
    }
}
