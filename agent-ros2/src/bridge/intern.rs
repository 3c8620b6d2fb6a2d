//! One definition per message name across a whole plan.
//!
//! ROS 2 has one definition per type name (`pkg/msg/Name`), and a
//! subscriber's type store keeps one: two topics whose messages define one
//! name differently would have one of them decoded with the other's
//! definition. The messages of each buffer type are made on their own, so
//! their helpers (`Item`, `Entry`, `Tuple`, `Unit`) and roots of one bare
//! name (`a::State`, `b::State`) may meet under one name. Here every
//! definition is interned across the plan: identical definitions (name,
//! constants, fields, and the definitions those fields use) share a name; a
//! definition whose name another already has gets it with the first free
//! number (`Item2`), and the fields that use it follow. (The same rule as
//! `embodied export --ros2`'s, on messages as data rather than text.)

use std::collections::{HashMap, HashSet};
use std::fmt::Write as _;

use agent_mcap::cdr::{BaseType, Message, Messages, MsgName};

/// The definitions met so far.
#[derive(Default)]
struct Interner {
    /// Each distinct definition's id, by its canonical text (fields naming
    /// the ids of the definitions they use).
    ids: HashMap<String, usize>,
    /// Each definition's name as made, by id.
    names: Vec<MsgName>,
}

impl Interner {
    /// The id of `m`, a message of `set`, after every message it uses;
    /// `local` keeps the ids of `set`'s messages. A field naming a message
    /// `set` lacks (or one met `depth` deep, in a cycle) keeps its name in
    /// the key: the type description then says what is wrong.
    fn intern(
        &mut self,
        set: &Messages,
        m: &Message,
        local: &mut HashMap<MsgName, usize>,
        depth: usize,
    ) -> usize {
        if let Some(&id) = local.get(&m.name) {
            return id;
        }
        let mut key = format!("{}\n{:?}\n", m.name, m.constants);
        for field in &m.fields {
            let _ = write!(key, "{} {:?} ", field.name, field.ty.arity);
            match &field.ty.base {
                BaseType::Message(n) if depth <= set.referenced.len() => {
                    match set.get(n).filter(|used| used.name != m.name) {
                        Some(used) => {
                            let id = self.intern(set, used, local, depth + 1);
                            let _ = write!(key, "#{id}");
                        }
                        None => key.push_str(&n.to_string()),
                    }
                }
                other => {
                    let _ = write!(key, "{other:?}");
                }
            }
            key.push('\n');
        }
        let next = self.names.len();
        let id = *self.ids.entry(key).or_insert(next);
        if id == next {
            self.names.push(m.name.clone());
        }
        local.insert(m.name.clone(), id);
        id
    }

    /// Every definition's name: the first of a name keeps it, the others
    /// get it with the first free number (`Item2`), never a name another
    /// definition was made with.
    fn named(&self) -> Vec<MsgName> {
        let wanted: HashSet<&MsgName> = self.names.iter().collect();
        let mut taken = HashSet::new();
        let mut out = Vec::with_capacity(self.names.len());
        for want in &self.names {
            let mut name = want.clone();
            let mut k = 1;
            while taken.contains(&name) || (k > 1 && wanted.contains(&name)) {
                k += 1;
                name = MsgName::new(want.package.clone(), format!("{}{k}", want.name));
            }
            taken.insert(name.clone());
            out.push(name);
        }
        out
    }
}

/// `sets` with one definition per name across them all, in the same order
/// (earlier sets keep their names first).
pub(crate) fn one_definition_per_name(sets: &[&Messages]) -> Vec<Messages> {
    let mut interner = Interner::default();
    let locals: Vec<HashMap<MsgName, usize>> = sets
        .iter()
        .map(|set| {
            let mut local = HashMap::new();
            for m in std::iter::once(&set.root).chain(&set.referenced) {
                interner.intern(set, m, &mut local, 0);
            }
            local
        })
        .collect();
    let names = interner.named();
    sets.iter()
        .zip(&locals)
        .map(|(set, local)| {
            set.renamed(|n| {
                local
                    .get(n)
                    .map_or_else(|| n.clone(), |&id| names[id].clone())
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use agent_mcap::cdr::{Field, FieldType, Primitive};

    fn item(p: Primitive, n: usize) -> Message {
        let ty = FieldType::primitive(p).array(n);
        Message::new(MsgName::new("pkg", "Item"), vec![Field::new("value", ty)])
    }

    fn holder(name: &str, item: Message) -> Messages {
        let field = FieldType::message(item.name.clone()).unbounded();
        Messages {
            root: Message::new(MsgName::new("pkg", name), vec![Field::new("rows", field)]),
            referenced: vec![item],
        }
    }

    #[test]
    fn a_name_defined_twice_is_numbered_and_its_users_follow() {
        let a = holder("State", item(Primitive::Float64, 4));
        let b = holder("State", item(Primitive::Float32, 3));
        let same = holder("Other", item(Primitive::Float64, 4));
        let out = one_definition_per_name(&[&a, &b, &same]);
        assert_eq!(out[0], a);
        assert_eq!(out[1].root.name, MsgName::new("pkg", "State2"));
        assert_eq!(out[1].referenced[0].name, MsgName::new("pkg", "Item2"));
        assert_eq!(
            out[1].root.fields[0].ty,
            FieldType::message(MsgName::new("pkg", "Item2")).unbounded()
        );
        // An identical definition keeps the name it shares.
        assert_eq!(out[2], same);
    }

    #[test]
    fn a_number_another_definition_was_made_with_is_skipped() {
        let item2 = Messages {
            root: Message::new(
                MsgName::new("pkg", "Item2"),
                vec![Field::new("x", FieldType::string())],
            ),
            referenced: Vec::new(),
        };
        let a = holder("A", item(Primitive::Float64, 4));
        let b = holder("B", item(Primitive::Float32, 3));
        let out = one_definition_per_name(&[&a, &b, &item2]);
        assert_eq!(out[1].referenced[0].name, MsgName::new("pkg", "Item3"));
        assert_eq!(out[2], item2);
    }
}
