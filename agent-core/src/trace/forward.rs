//! The observers that forward to others: a [`Box`]ed observer, a pair of
//! observers of one run, an [`Option`]al observer. Each forwards every hook,
//! so that a wrapper costs nothing a hook's default would not.

use crate::error::ExecError;
use crate::fsm::Valuation;
use crate::time::Time;

use super::{
    ActionEvent, AuditEvent, ErasedPayload, LinkEvents, NodeEvents, Observer, ReadEvent,
    SendStamps, SystemInfo, TransferEvent, TransitionEvent,
};

/// A boxed observer observes as the box's content does.
impl<O: Observer + ?Sized> Observer for Box<O> {
    fn enabled(&self) -> bool {
        (**self).enabled()
    }
    fn start(&mut self, system: &SystemInfo) {
        (**self).start(system);
    }
    fn transition(&mut self, event: &TransitionEvent) {
        (**self).transition(event);
    }
    fn action(&mut self, event: &ActionEvent) {
        (**self).action(event);
    }
    fn audit(&mut self, event: &AuditEvent) {
        (**self).audit(event);
    }
    fn link_events(&self, link: usize) -> LinkEvents {
        (**self).link_events(link)
    }
    fn node_events(&self, node: usize) -> NodeEvents {
        (**self).node_events(node)
    }
    fn instant(&mut self, time: Time) {
        (**self).instant(time);
    }
    fn stamps(&mut self, stamps: &SendStamps) {
        (**self).stamps(stamps);
    }
    fn transfer(&mut self, event: &TransferEvent, value: &dyn ErasedPayload) {
        (**self).transfer(event, value);
    }
    fn read(&mut self, event: &ReadEvent) {
        (**self).read(event);
    }
    fn held(&mut self, event: &ReadEvent) {
        (**self).held(event);
    }
    fn received(&mut self, event: &ReadEvent, value: &dyn ErasedPayload) {
        (**self).received(event, value);
    }
    fn error(&mut self, time: Time, error: &ExecError) {
        (**self).error(time, error);
    }
    fn predicates_wanted(&self, node: usize) -> u64 {
        (**self).predicates_wanted(node)
    }
    fn predicates(&mut self, event: &ActionEvent, values: Valuation) {
        (**self).predicates(event, values);
    }
    fn raised(&mut self) -> Option<ExecError> {
        (**self).raised()
    }
}

/// Two observers of one run (a recorder and a printer, say): each event goes to
/// the first, then to the second, to each only if it is enabled.
impl<A: Observer, B: Observer> Observer for (A, B) {
    fn enabled(&self) -> bool {
        self.0.enabled() || self.1.enabled()
    }
    fn start(&mut self, system: &SystemInfo) {
        if self.0.enabled() {
            self.0.start(system);
        }
        if self.1.enabled() {
            self.1.start(system);
        }
    }
    fn transition(&mut self, event: &TransitionEvent) {
        if self.0.enabled() {
            self.0.transition(event);
        }
        if self.1.enabled() {
            self.1.transition(event);
        }
    }
    fn action(&mut self, event: &ActionEvent) {
        if self.0.enabled() {
            self.0.action(event);
        }
        if self.1.enabled() {
            self.1.action(event);
        }
    }
    fn audit(&mut self, event: &AuditEvent) {
        if self.0.enabled() {
            self.0.audit(event);
        }
        if self.1.enabled() {
            self.1.audit(event);
        }
    }
    fn link_events(&self, link: usize) -> LinkEvents {
        let events = |o: &dyn Observer| {
            if o.enabled() {
                o.link_events(link)
            } else {
                LinkEvents::none()
            }
        };
        events(&self.0).union(events(&self.1))
    }
    fn node_events(&self, node: usize) -> NodeEvents {
        let events = |o: &dyn Observer| {
            if o.enabled() {
                o.node_events(node)
            } else {
                NodeEvents::none()
            }
        };
        events(&self.0).union(events(&self.1))
    }
    fn instant(&mut self, time: Time) {
        if self.0.enabled() {
            self.0.instant(time);
        }
        if self.1.enabled() {
            self.1.instant(time);
        }
    }
    fn stamps(&mut self, stamps: &SendStamps) {
        if self.0.enabled() {
            self.0.stamps(stamps);
        }
        if self.1.enabled() {
            self.1.stamps(stamps);
        }
    }
    fn transfer(&mut self, event: &TransferEvent, value: &dyn ErasedPayload) {
        if self.0.enabled() {
            self.0.transfer(event, value);
        }
        if self.1.enabled() {
            self.1.transfer(event, value);
        }
    }
    fn read(&mut self, event: &ReadEvent) {
        if self.0.enabled() {
            self.0.read(event);
        }
        if self.1.enabled() {
            self.1.read(event);
        }
    }
    fn held(&mut self, event: &ReadEvent) {
        if self.0.enabled() {
            self.0.held(event);
        }
        if self.1.enabled() {
            self.1.held(event);
        }
    }
    fn received(&mut self, event: &ReadEvent, value: &dyn ErasedPayload) {
        if self.0.enabled() {
            self.0.received(event, value);
        }
        if self.1.enabled() {
            self.1.received(event, value);
        }
    }
    fn error(&mut self, time: Time, error: &ExecError) {
        if self.0.enabled() {
            self.0.error(time, error);
        }
        if self.1.enabled() {
            self.1.error(time, error);
        }
    }
    fn predicates_wanted(&self, node: usize) -> u64 {
        let a = if self.0.enabled() {
            self.0.predicates_wanted(node)
        } else {
            0
        };
        let b = if self.1.enabled() {
            self.1.predicates_wanted(node)
        } else {
            0
        };
        a | b
    }
    fn predicates(&mut self, event: &ActionEvent, values: Valuation) {
        if self.0.enabled() {
            self.0.predicates(event, values);
        }
        if self.1.enabled() {
            self.1.predicates(event, values);
        }
    }
    fn raised(&mut self) -> Option<ExecError> {
        let first = if self.0.enabled() {
            self.0.raised()
        } else {
            None
        };
        first.or_else(|| {
            if self.1.enabled() {
                self.1.raised()
            } else {
                None
            }
        })
    }
}

/// An observer that may be absent: observes as its content does, if any.
impl<O: Observer> Observer for Option<O> {
    fn enabled(&self) -> bool {
        self.as_ref().is_some_and(Observer::enabled)
    }
    fn start(&mut self, system: &SystemInfo) {
        if let Some(o) = self {
            o.start(system);
        }
    }
    fn transition(&mut self, event: &TransitionEvent) {
        if let Some(o) = self {
            o.transition(event);
        }
    }
    fn action(&mut self, event: &ActionEvent) {
        if let Some(o) = self {
            o.action(event);
        }
    }
    fn audit(&mut self, event: &AuditEvent) {
        if let Some(o) = self {
            o.audit(event);
        }
    }
    fn link_events(&self, link: usize) -> LinkEvents {
        self.as_ref()
            .map_or_else(LinkEvents::none, |o| o.link_events(link))
    }
    fn node_events(&self, node: usize) -> NodeEvents {
        self.as_ref()
            .map_or_else(NodeEvents::none, |o| o.node_events(node))
    }
    fn instant(&mut self, time: Time) {
        if let Some(o) = self {
            o.instant(time);
        }
    }
    fn stamps(&mut self, stamps: &SendStamps) {
        if let Some(o) = self {
            o.stamps(stamps);
        }
    }
    fn transfer(&mut self, event: &TransferEvent, value: &dyn ErasedPayload) {
        if let Some(o) = self {
            o.transfer(event, value);
        }
    }
    fn read(&mut self, event: &ReadEvent) {
        if let Some(o) = self {
            o.read(event);
        }
    }
    fn held(&mut self, event: &ReadEvent) {
        if let Some(o) = self {
            o.held(event);
        }
    }
    fn received(&mut self, event: &ReadEvent, value: &dyn ErasedPayload) {
        if let Some(o) = self {
            o.received(event, value);
        }
    }
    fn error(&mut self, time: Time, error: &ExecError) {
        if let Some(o) = self {
            o.error(time, error);
        }
    }
    fn predicates_wanted(&self, node: usize) -> u64 {
        self.as_ref().map_or(0, |o| o.predicates_wanted(node))
    }
    fn predicates(&mut self, event: &ActionEvent, values: Valuation) {
        if let Some(o) = self {
            o.predicates(event, values);
        }
    }
    fn raised(&mut self) -> Option<ExecError> {
        self.as_mut().and_then(Observer::raised)
    }
}
