//! The messages of a [`TypeShape`]: the mapping of the parent module's table,
//! as [`Message`]s of one package.

use std::collections::{BTreeMap, BTreeSet};

use agent_core::TypeShape;
use agent_core::serde_reflection::{ContainerFormat, Format, Named, VariantFormat};

use super::Unsupported;
use super::model::{
    Arity, BaseType, Constant, Field, FieldType, Message, Messages, MsgName, Primitive,
};

/// The messages of the values [`write_cdr`](super::write_cdr) makes for
/// `shape`, in `package`; `root` names the root message when the type is not
/// a named struct or enum itself (a sequence, a primitive). The referenced
/// messages are in the order they were made (each after those it uses).
pub fn messages(shape: &TypeShape, package: &str, root: &str) -> Result<Messages, Unsupported> {
    let mut g = Gen {
        shape,
        package,
        defs: Vec::new(),
        taken: BTreeSet::new(),
        named: BTreeMap::new(),
        open: BTreeSet::new(),
    };
    let ty = g.ty(&shape.root)?;
    let name = match ty {
        FieldType {
            base: BaseType::Message(name),
            arity: Arity::One,
        } => name,
        other => {
            let name = g.fresh(&message_name(root));
            g.defs
                .push(Message::new(name.clone(), vec![Field::new("value", other)]));
            name
        }
    };
    let at = g.defs.iter().position(|m| m.name == name);
    let root = at
        .map(|k| g.defs.remove(k))
        .ok_or_else(|| Unsupported(format!("no message was made for `{name}`")))?;
    Ok(Messages {
        root,
        referenced: g.defs,
    })
}

struct Gen<'a> {
    shape: &'a TypeShape,
    package: &'a str,
    /// The messages, in the order made.
    defs: Vec<Message>,
    taken: BTreeSet<String>,
    /// Named types already made, by serde name.
    named: BTreeMap<&'a str, FieldType>,
    /// Named types being made (a type met inside itself is recursive).
    open: BTreeSet<&'a str>,
}

fn prim(p: Primitive) -> FieldType {
    FieldType::primitive(p)
}

impl<'a> Gen<'a> {
    /// `base`, or `base2`, `base3`, ... whichever is free, in the package.
    fn fresh(&mut self, base: &str) -> MsgName {
        let mut name = base.to_owned();
        let mut k = 2;
        while self.taken.contains(&name) {
            name = format!("{base}{k}");
            k += 1;
        }
        self.taken.insert(name.clone());
        MsgName::new(self.package, name)
    }

    /// A message of these fields (an empty one if there are none).
    fn message(&mut self, base: &str, fields: Vec<Field>) -> Result<FieldType, Unsupported> {
        let name = self.fresh(base);
        let mut seen = BTreeSet::new();
        for field in &fields {
            if !field_name_ok(&field.name) || !seen.insert(field.name.as_str()) {
                return Err(Unsupported(format!(
                    "the field `{}` of `{}` (ROS 2 field names are lower case \
                     letters, digits and single underscores, unique)",
                    field.name, name.name
                )));
            }
        }
        self.defs.push(Message::new(name.clone(), fields));
        Ok(FieldType::message(name))
    }

    /// The type of an array's elements: arrays wrapped in a message.
    fn element(&mut self, f: &'a Format) -> Result<BaseType, Unsupported> {
        let t = self.ty(f)?;
        if t.arity == Arity::One {
            return Ok(t.base);
        }
        Ok(self.message("Item", vec![Field::new("value", t)])?.base)
    }

    fn items(&mut self, fs: &'a [Format]) -> Result<Vec<Field>, Unsupported> {
        fs.iter()
            .enumerate()
            .map(|(k, f)| Ok(Field::new(format!("item{k}"), self.ty(f)?)))
            .collect()
    }

    fn fields(&mut self, fs: &'a [Named<Format>]) -> Result<Vec<Field>, Unsupported> {
        fs.iter()
            .map(|f| Ok(Field::new(f.name.clone(), self.ty(&f.value)?)))
            .collect()
    }

    fn ty(&mut self, f: &'a Format) -> Result<FieldType, Unsupported> {
        let of = |base: BaseType| FieldType {
            base,
            arity: Arity::One,
        };
        Ok(match f {
            Format::Unit => self.message("Unit", Vec::new())?,
            Format::Bool => prim(Primitive::Bool),
            Format::U8 => prim(Primitive::Uint8),
            Format::U16 => prim(Primitive::Uint16),
            Format::U32 | Format::Char => prim(Primitive::Uint32),
            Format::U64 => prim(Primitive::Uint64),
            Format::I8 => prim(Primitive::Int8),
            Format::I16 => prim(Primitive::Int16),
            Format::I32 => prim(Primitive::Int32),
            Format::I64 => prim(Primitive::Int64),
            Format::U128 | Format::I128 => prim(Primitive::Uint8).array(16),
            Format::F32 => prim(Primitive::Float32),
            Format::F64 => prim(Primitive::Float64),
            Format::Str => FieldType::string(),
            Format::Bytes => prim(Primitive::Uint8).unbounded(),
            Format::Option(inner) => of(self.element(inner)?).bounded(1),
            Format::Seq(inner) => of(self.element(inner)?).unbounded(),
            Format::TupleArray { content, size } => of(self.element(content)?).array(*size),
            Format::Map { key, value } => {
                let fields = vec![
                    Field::new("key", self.ty(key)?),
                    Field::new("value", self.ty(value)?),
                ];
                self.message("Entry", fields)?.unbounded()
            }
            Format::Tuple(items) => {
                let fields = self.items(items)?;
                self.message("Tuple", fields)?
            }
            Format::TypeName(name) => self.named(name)?,
            Format::Variable(_) => {
                return Err(Unsupported("a format left unknown by the tracer".into()));
            }
        })
    }

    fn named(&mut self, name: &'a str) -> Result<FieldType, Unsupported> {
        if let Some(t) = self.named.get(name) {
            return Ok(t.clone());
        }
        let shape = self.shape;
        let c = shape
            .registry
            .get(name)
            .ok_or_else(|| Unsupported(format!("`{name}` is not in the shape")))?;
        if !self.open.insert(name) {
            return Err(Unsupported(format!("`{name}` contains itself")));
        }
        let base = message_name(name);
        let t = match c {
            ContainerFormat::UnitStruct => self.message(&base, Vec::new()),
            ContainerFormat::NewTypeStruct(f) => self.ty(f),
            ContainerFormat::TupleStruct(fs) => self
                .items(fs)
                .and_then(|fields| self.message(&base, fields)),
            ContainerFormat::Struct(fs) => self
                .fields(fs)
                .and_then(|fields| self.message(&base, fields)),
            ContainerFormat::Enum(variants) => self.enumeration(&base, variants),
        };
        self.open.remove(name);
        let t = t?;
        self.named.insert(name, t.clone());
        Ok(t)
    }

    fn enumeration(
        &mut self,
        base: &str,
        variants: &'a BTreeMap<u32, Named<VariantFormat>>,
    ) -> Result<FieldType, Unsupported> {
        let mut constants = Vec::new();
        let mut fields = vec![Field::new("variant", prim(Primitive::Uint32))];
        for (k, v) in variants {
            let constant = constant_name(&v.name);
            if !constant_name_ok(&constant)
                || constants.iter().any(|c: &Constant| c.name == constant)
            {
                return Err(Unsupported(format!(
                    "the variant `{}` of `{base}` as the constant `{constant}` (ROS 2 \
                     constant names are upper case letters, digits and single \
                     underscores, unique)",
                    v.name
                )));
            }
            constants.push(Constant {
                name: constant,
                ty: Primitive::Uint32,
                value: k.to_string(),
            });
            let data = match &v.value {
                VariantFormat::Unit => continue,
                VariantFormat::NewType(f) => self.element(f)?,
                VariantFormat::Tuple(fs) => {
                    let items = self.items(fs)?;
                    let name = format!("{base}{}", message_name(&v.name));
                    self.message(&name, items)?.base
                }
                VariantFormat::Struct(fs) => {
                    let named = self.fields(fs)?;
                    let name = format!("{base}{}", message_name(&v.name));
                    self.message(&name, named)?.base
                }
                VariantFormat::Variable(_) => {
                    return Err(Unsupported("a variant left unknown by the tracer".into()));
                }
            };
            let ty = FieldType {
                base: data,
                arity: Arity::One,
            };
            fields.push(Field::new(snake(&v.name), ty.bounded(1)));
        }
        let t = self.message(base, fields)?;
        // The constants go before the fields.
        if let Some(m) = self.defs.last_mut() {
            m.constants = constants;
        }
        Ok(t)
    }
}

/// A ROS 2 message name (`^[A-Z][A-Za-z0-9]*$`) from a Rust type name.
pub(super) fn message_name(name: &str) -> String {
    let mut out: String = name
        .split(|c: char| !c.is_ascii_alphanumeric())
        .filter(|p| !p.is_empty())
        .map(|p| {
            let mut cs = p.chars();
            cs.next()
                .map(|c| c.to_ascii_uppercase().to_string() + cs.as_str())
                .unwrap_or_default()
        })
        .collect();
    if !out.starts_with(|c: char| c.is_ascii_uppercase()) {
        out.insert(0, 'T');
    }
    out
}

/// `NoEstimate` -> `no_estimate`.
pub(super) fn snake(name: &str) -> String {
    let mut out = String::new();
    for (k, c) in name.chars().enumerate() {
        if c.is_ascii_uppercase() {
            if k > 0 && !out.ends_with('_') {
                out.push('_');
            }
            out.push(c.to_ascii_lowercase());
        } else if c.is_ascii_alphanumeric() {
            out.push(c);
        } else if !out.ends_with('_') {
            out.push('_');
        }
    }
    out
}

/// `NoEstimate` -> `NO_ESTIMATE`.
pub(super) fn constant_name(name: &str) -> String {
    let s = snake(name).to_ascii_uppercase();
    if s.starts_with(|c: char| c.is_ascii_uppercase()) {
        s
    } else {
        format!("V{s}")
    }
}

/// ROS 2's constant names: `^[A-Z]([A-Z0-9_]?[A-Z0-9]+)*$`.
fn constant_name_ok(name: &str) -> bool {
    ros_name_ok(name, |c| c.is_ascii_uppercase())
}

/// ROS 2's field names: `^[a-z]([a-z0-9_]?[a-z0-9]+)*$`.
pub(super) fn field_name_ok(name: &str) -> bool {
    ros_name_ok(name, |c| c.is_ascii_lowercase())
}

/// A name of `letter`s, digits and single underscores, starting with a letter
/// and not ending with an underscore.
fn ros_name_ok(name: &str, letter: fn(&char) -> bool) -> bool {
    name.starts_with(|c: char| letter(&c))
        && name
            .chars()
            .all(|c| letter(&c) || c.is_ascii_digit() || c == '_')
        && !name.contains("__")
        && !name.ends_with('_')
}
