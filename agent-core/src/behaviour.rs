//! Behaviours: an elementary action repeated while or until a terminal condition
//! (Algorithms 2 and 3 of the paper).

use std::borrow::Cow;
use std::fmt;

use crate::kinds::BehaviourKind;
use crate::subsystem::Subsystem;
use crate::transition::Action;

/// A behaviour `B_{j,m}(f_{j,m}, f^τ_{j,m})`: a named loop of one elementary action
/// with a terminal condition.
///
/// The terminal condition is a Boolean expression over the FSM's named predicates
/// (for instance `"plan_done && !ready"`, or `"false"` for a behaviour that never
/// ends); it is resolved when the FSM is built.
#[repr(C)]
pub struct Behaviour<S: Subsystem> {
    // The kind and the action's slice of parts first: what an action reads
    // (the FSM's node is `repr(C)` too).
    pub(crate) kind: BehaviourKind,
    pub(crate) action: Action<S>,
    pub(crate) name: Cow<'static, str>,
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
