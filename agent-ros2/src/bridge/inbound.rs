//! The plan of a subscribed topic: from a spec's `subscribe` entry and a
//! built system, the link whose input buffer the topic feeds, the message
//! (the buffer type's own, or a standard one read by an adapter), its key
//! and QoS, and how a message received becomes the buffer type's postcard
//! bytes.

use agent_core::{System, SystemInfo};
use agent_spec::ros2::{Interface as SpecInterface, Topic};

use super::adapter::{Adapters, Decoder};
use super::plan::{PlanError, message_plan};
use crate::types::Messages;
use crate::wire::{Qos, TopicKey};

/// One ROS 2 topic feeding one input buffer.
#[derive(Clone)]
pub struct SubscribedTopic {
    /// The input buffer, `component.peer.buffer`: an input of `component`
    /// fed by `peer`.
    pub buffer: String,
    /// The link into that input (its index in the system's links): the
    /// topic's values are taken by the input's reads beside the link's own.
    pub link: usize,
    /// The buffer's Rust type.
    pub payload: &'static str,
    /// The buffer type's fingerprint: an inbox of another type is refused
    /// ([`Bridge::subscribe`](super::Bridge::subscribe)).
    pub fingerprint: u64,
    /// The message and every message it uses (their `.msg` texts).
    pub messages: Messages,
    /// The data key: domain, fully qualified topic, type and type hash. A
    /// message on the topic of another type or hash is refused.
    pub key: TopicKey,
    /// The quality of service the subscription announces.
    pub qos: Qos,
    pub(crate) decoder: Decoder,
}

impl std::fmt::Debug for SubscribedTopic {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SubscribedTopic")
            .field("buffer", &self.buffer)
            .field("link", &self.link)
            .field("key", &self.key.to_string())
            .field("qos", &self.qos.to_compact())
            .finish()
    }
}

impl SubscribedTopic {
    /// Whether the message is the buffer type's own (else a standard one,
    /// read by an adapter).
    pub(crate) fn is_own(&self) -> bool {
        self.decoder.is_own()
    }
}

/// The plan of one subscribed input buffer.
pub(crate) fn subscribed(
    t: &Topic,
    interface: &SpecInterface,
    system: &System,
    adapters: &Adapters,
) -> Result<SubscribedTopic, PlanError> {
    let link = input_link_of(system.info(), &t.buffer).ok_or_else(|| PlanError::NoInputLink {
        buffer: t.buffer.clone(),
        topic: t.name.clone(),
    })?;
    let payload = system.info().links[link].payload;
    let fingerprint = system.payload_fingerprint(link).unwrap_or(0);
    let plan = message_plan(
        t,
        interface,
        system,
        link,
        payload,
        |message, fingerprint| {
            let adapter = adapters.find_inbound(fingerprint, message).ok_or_else(|| {
                PlanError::NoInboundAdapter {
                    buffer: t.buffer.clone(),
                    topic: t.name.clone(),
                    payload: payload.to_owned(),
                    message: message.to_owned(),
                    available: adapters.inbound_messages_of(fingerprint),
                }
            })?;
            Ok((adapter.traceable, &adapter.messages, &adapter.make))
        },
    )?;
    Ok(SubscribedTopic {
        buffer: t.buffer.clone(),
        link,
        payload,
        fingerprint,
        messages: plan.messages,
        key: plan.key,
        qos: plan.qos,
        decoder: plan.conversion,
    })
}

/// The first link whose values go into input `component.peer.buffer`.
fn input_link_of(info: &SystemInfo, buffer: &str) -> Option<usize> {
    let (component, port) = buffer.split_once('.')?;
    let node = info.nodes.iter().position(|n| n.name == component)?;
    info.links
        .iter()
        .position(|l| l.to == node && l.to_port == port)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bridge::adapter::Refusal;
    use agent_core::reflect;

    #[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
    struct Point {
        x: f64,
        label: String,
    }

    /// The own decoder reads what the recorder's transcoder writes, and
    /// refuses a message cut short, naming the offset.
    #[test]
    fn an_own_decoder_reads_the_cdr_of_its_type() {
        let shape = reflect::<Point>().unwrap_or_else(|| panic!("no shape"));
        let json = serde_json::to_string(&(&shape.root, &shape.registry))
            .unwrap_or_else(|e| panic!("{e}"));
        let Some(ready) = Decoder::Own(json).ready() else {
            panic!("not ready")
        };
        let value = Point {
            x: 1.5,
            label: "here".into(),
        };
        let mut cdr = Vec::new();
        crate::types::encode_cdr(&value, &shape, &mut cdr).unwrap_or_else(|e| panic!("{e}"));
        let mut out = Vec::new();
        assert_eq!(ready.decode(&cdr, &mut out), Ok(()));
        assert_eq!(postcard::from_bytes::<Point>(&out), Ok(value));
        let mut out = Vec::new();
        let Err(Refusal::Undecodable(why)) = ready.decode(&cdr[..cdr.len() - 3], &mut out) else {
            panic!("a message cut short was read")
        };
        assert!(why.starts_with("byte "), "{why}");
    }
}
