//! A payload type's shape (its serde data model, traced with
//! `serde-reflection`) and the fingerprint made of it, which links between
//! processes check.

use std::hash::Hasher;

use crate::buffer::Payload;

/// A 64-bit fingerprint of the payload type `T`'s shape: its serde data model
/// (names of structs, fields, enum variants, and the types within them), traced
/// with `serde-reflection`, hashed with FNV-1a. Two processes agree on it when
/// their payload types serialise alike; a field added, renamed or retyped
/// changes it. A type that cannot be traced (a custom `Deserialize` that
/// rejects the tracer's samples) falls back to the hash of its Rust type name.
pub fn fingerprint<T: Payload>() -> u64 {
    let mut hash = Fnv::default();
    match reflect::<T>() {
        Some(shape) => {
            hash.write(format!("{:?}", shape.root).as_bytes());
            for (name, container) in &shape.registry {
                hash.write(name.as_bytes());
                hash.write(format!("{container:?}").as_bytes());
            }
        }
        None => hash.write(std::any::type_name::<T>().as_bytes()),
    }
    hash.finish()
}

/// A payload type's serde data model, traced with `serde-reflection`: the
/// format of the value and the formats of the named types within it. With it,
/// a value's postcard bytes can be read without the type (to show them as
/// JSON in a recording, for example).
#[derive(Clone, Debug, PartialEq)]
pub struct TypeShape {
    /// The value's format.
    pub root: serde_reflection::Format,
    /// The named containers (structs, enums) it refers to.
    pub registry: serde_reflection::Registry,
}

/// The shape of `T`, or `None` for a type the tracer cannot follow (a custom
/// `Deserialize` that rejects its samples).
///
/// Every variant of every enum within `T` is explored, not only the root's
/// (`serde-reflection` explores the root enum's; the names of the enums nested
/// in it come from a first trace, and each later pass explores their next
/// variants as it does the root's). An enum reached only through a sequence,
/// an option or a map cannot be explored past its first variant (the tracer
/// stops at the first element of those); such a type has no shape (`None`),
/// rather than one that misses variants.
pub fn reflect<T: Payload>() -> Option<TypeShape> {
    use serde_reflection::{Error, Format, Samples, Tracer, TracerConfig};
    let samples = Samples::new();
    let mut enums: std::collections::BTreeSet<String> = std::collections::BTreeSet::new();
    // Each round may discover enums nested in variants found in the last one.
    for _ in 0..16 {
        let mut tracer = Tracer::new(TracerConfig::default());
        let mut root = None;
        for _ in 0..10_000 {
            let (format, _) = tracer.trace_type_once::<T>(&samples).ok()?;
            let mut incomplete = false;
            if let Format::TypeName(name) = &format {
                incomplete |= tracer.check_incomplete_enum(name).is_some();
            }
            for name in &enums {
                incomplete |= tracer.check_incomplete_enum(name).is_some();
            }
            root = Some(format);
            if !incomplete {
                break;
            }
        }
        match tracer.registry() {
            // An enum whose exploration stopped keeps a provisional number
            // (counted down from `u32::MAX`) for a variant it met by name only.
            Ok(registry) => {
                let explored = registry.values().all(|c| match c {
                    serde_reflection::ContainerFormat::Enum(variants) => {
                        variants.keys().all(|k| *k < u32::MAX / 2)
                    }
                    _ => true,
                });
                return explored.then_some(TypeShape {
                    root: root?,
                    registry,
                });
            }
            Err(Error::MissingVariants(missing)) => {
                let known = enums.len();
                enums.extend(missing);
                if enums.len() == known {
                    return None;
                }
            }
            Err(_) => return None,
        }
    }
    None
}

/// FNV-1a, 64 bits: stable across Rust versions and platforms (unlike
/// `DefaultHasher`), which a fingerprint sent between builds must be.
pub(crate) struct Fnv(u64);

impl Default for Fnv {
    fn default() -> Self {
        Fnv(0xcbf2_9ce4_8422_2325)
    }
}

impl Hasher for Fnv {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for b in bytes {
            self.0 ^= u64::from(*b);
            self.0 = self.0.wrapping_mul(0x0100_0000_01b3);
        }
    }
}
