//! A buffer value's postcard bytes as JSON, and the JSON schema of its type,
//! both read off the type's [`TypeShape`] (its serde data model).
//!
//! The JSON is what `serde_json` makes of the value itself: structs as objects,
//! enums externally tagged (`"Unit"`, `{"Variant": ...}`), tuples and arrays as
//! arrays, `None` as `null`, non-finite floats as `null`, map keys as strings.
//! Integers beyond what JSON numbers carry exactly (128-bit ones outside the
//! 64-bit range) become strings.

use std::collections::BTreeSet;

use agent_core::TypeShape;
use agent_core::serde_reflection::{ContainerFormat, Format, Named, VariantFormat};
use serde_json::{Map, Value, json};

pub use crate::postcard::DecodeError;
use crate::postcard::{Cursor, MAX_DEPTH};

/// The value encoded (postcard) in `bytes`, as JSON, read with `shape`. All
/// the bytes must be used.
pub fn to_json(shape: &TypeShape, bytes: &[u8]) -> Result<Value, DecodeError> {
    let mut text = Vec::with_capacity(bytes.len() * 4);
    write_json(shape, bytes, &mut text)?;
    serde_json::from_slice(&text).map_err(|e| DecodeError {
        offset: 0,
        what: format!("the JSON written does not read back: {e}"),
    })
}

/// [`to_json`] as text, appended to `out` without building the value: what
/// the recorder's writer thread does for every value (a `Value` tree costs an
/// allocation per field and per element). Struct fields keep their declared
/// order. On an error `out` holds a part of the text.
pub fn write_json(shape: &TypeShape, bytes: &[u8], out: &mut Vec<u8>) -> Result<(), DecodeError> {
    let mut r = Reader {
        shape,
        c: Cursor::new(bytes),
        depth: 0,
        out,
    };
    r.value(&shape.root)?;
    r.c.end()
}

struct Reader<'a> {
    shape: &'a TypeShape,
    c: Cursor<'a>,
    depth: usize,
    out: &'a mut Vec<u8>,
}

/// Appends `v`'s JSON text (`serde_json`'s: shortest round-trip floats,
/// escaped strings) to `out`; writing to a `Vec` cannot fail.
fn emit<T: serde::Serialize + ?Sized>(out: &mut Vec<u8>, v: &T) {
    let _ = serde_json::to_writer(out, v);
}

impl Reader<'_> {
    fn value(&mut self, f: &Format) -> Result<(), DecodeError> {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            return Err(self.c.fail(format!("nested deeper than {MAX_DEPTH}")));
        }
        let v = self.inner(f);
        self.depth -= 1;
        v
    }

    /// `n` values of `f` (or of each of `items`) as a JSON array.
    fn array<'f>(&mut self, formats: impl Iterator<Item = &'f Format>) -> Result<(), DecodeError> {
        self.out.push(b'[');
        for (k, f) in formats.enumerate() {
            if k > 0 {
                self.out.push(b',');
            }
            self.value(f)?;
        }
        self.out.push(b']');
        Ok(())
    }

    fn inner(&mut self, f: &Format) -> Result<(), DecodeError> {
        match f {
            Format::Unit => self.out.extend_from_slice(b"null"),
            Format::Bool => match self.c.byte()? {
                0 => self.out.extend_from_slice(b"false"),
                1 => self.out.extend_from_slice(b"true"),
                b => {
                    self.c.at -= 1;
                    return Err(self.c.fail(format!("a bool byte of {b}")));
                }
            },
            Format::U8 => {
                let v = self.c.byte()?;
                emit(self.out, &v);
            }
            Format::I8 => {
                let v = self.c.byte()? as i8;
                emit(self.out, &v);
            }
            Format::U16 | Format::U32 | Format::U64 | Format::U128 => {
                let bits = match f {
                    Format::U16 => 16,
                    Format::U32 => 32,
                    Format::U64 => 64,
                    _ => 128,
                };
                let v = self.c.varint(bits)?;
                // Beyond 64 bits a JSON number is not exact: a string.
                match u64::try_from(v) {
                    Ok(v) => emit(self.out, &v),
                    Err(_) => emit(self.out, &v.to_string()),
                }
            }
            Format::I16 | Format::I32 | Format::I64 | Format::I128 => {
                let bits = match f {
                    Format::I16 => 16,
                    Format::I32 => 32,
                    Format::I64 => 64,
                    _ => 128,
                };
                let v = self.c.signed(bits)?;
                match i64::try_from(v) {
                    Ok(v) => emit(self.out, &v),
                    Err(_) => emit(self.out, &v.to_string()),
                }
            }
            Format::F32 => {
                let b = self.c.array::<4>()?;
                // As `serde_json` writes an f32 widened to f64 (non-finite: null).
                emit(self.out, &f64::from(f32::from_le_bytes(b)));
            }
            Format::F64 => {
                let b = self.c.array::<8>()?;
                emit(self.out, &f64::from_le_bytes(b));
            }
            Format::Char | Format::Str => self.string()?,
            Format::Bytes => self.bytes()?,
            Format::Option(inner) => match self.c.byte()? {
                0 => self.out.extend_from_slice(b"null"),
                1 => self.value(inner)?,
                b => {
                    self.c.at -= 1;
                    return Err(self.c.fail(format!("an option tag of {b}")));
                }
            },
            Format::Seq(inner) => {
                let n = self.c.length()?;
                self.array(std::iter::repeat_n(&**inner, n))?;
            }
            Format::Map { key, value } => self.map(key, value)?,
            Format::Tuple(items) => self.array(items.iter())?,
            Format::TupleArray { content, size } => {
                self.array(std::iter::repeat_n(&**content, *size))?;
            }
            Format::TypeName(name) => {
                let c = self.c.container(self.shape, name)?;
                self.container(c)?;
            }
            Format::Variable(_) => {
                return Err(self.c.fail("a format left unknown by the tracer".into()));
            }
        }
        Ok(())
    }

    /// A char or a string as a JSON string.
    fn string(&mut self) -> Result<(), DecodeError> {
        let n = self.c.length()?;
        let at = self.c.at;
        self.c.take(n)?;
        let bytes: &[u8] = self.c.bytes;
        let s = std::str::from_utf8(&bytes[at..at + n]).map_err(|e| DecodeError {
            offset: at,
            what: format!("a string that is not UTF-8: {e}"),
        })?;
        emit(self.out, s);
        Ok(())
    }

    /// Bytes as a JSON array of numbers.
    fn bytes(&mut self) -> Result<(), DecodeError> {
        let n = self.c.length()?;
        let at = self.c.at;
        self.c.take(n)?;
        self.out.push(b'[');
        for k in 0..n {
            if k > 0 {
                self.out.push(b',');
            }
            let b = self.c.bytes[at + k];
            emit(self.out, &b);
        }
        self.out.push(b']');
        Ok(())
    }

    /// A map as a JSON object.
    fn map(&mut self, key: &Format, value: &Format) -> Result<(), DecodeError> {
        let n = self.c.length()?;
        self.out.push(b'{');
        for k in 0..n {
            if k > 0 {
                self.out.push(b',');
            }
            // The key as an object key must be: a string as it is,
            // anything else as its JSON text, quoted.
            let start = self.out.len();
            self.value(key)?;
            if self.out.get(start) != Some(&b'"') {
                let text = String::from_utf8_lossy(&self.out[start..]).into_owned();
                self.out.truncate(start);
                emit(self.out, &text);
            }
            self.out.push(b':');
            self.value(value)?;
        }
        self.out.push(b'}');
        Ok(())
    }

    fn container(&mut self, c: &ContainerFormat) -> Result<(), DecodeError> {
        match c {
            ContainerFormat::UnitStruct => self.out.extend_from_slice(b"null"),
            ContainerFormat::NewTypeStruct(f) => self.value(f)?,
            ContainerFormat::TupleStruct(fs) => self.array(fs.iter())?,
            ContainerFormat::Struct(fields) => self.fields(fields)?,
            ContainerFormat::Enum(variants) => {
                let at = self.c.at;
                let k = self.c.varint(32)?;
                let Some(v) = u32::try_from(k).ok().and_then(|k| variants.get(&k)) else {
                    return Err(DecodeError {
                        offset: at,
                        what: format!("variant {k} of an enum of {}", variants.len()),
                    });
                };
                if let VariantFormat::Unit = v.value {
                    emit(self.out, &v.name);
                    return Ok(());
                }
                self.out.push(b'{');
                emit(self.out, &v.name);
                self.out.push(b':');
                match &v.value {
                    VariantFormat::NewType(f) => self.value(f)?,
                    VariantFormat::Tuple(fs) => self.array(fs.iter())?,
                    VariantFormat::Struct(fields) => self.fields(fields)?,
                    VariantFormat::Unit => {}
                    VariantFormat::Variable(_) => {
                        return Err(self.c.fail("a variant left unknown by the tracer".into()));
                    }
                }
                self.out.push(b'}');
            }
        }
        Ok(())
    }

    fn fields(&mut self, fields: &[Named<Format>]) -> Result<(), DecodeError> {
        self.out.push(b'{');
        for (k, f) in fields.iter().enumerate() {
            if k > 0 {
                self.out.push(b',');
            }
            emit(self.out, &f.name);
            self.out.push(b':');
            self.value(&f.value)?;
        }
        self.out.push(b'}');
        Ok(())
    }
}

/// The JSON schema (draft 2020-12) of the values [`to_json`] makes for
/// `shape`, titled `title`. Named types are written out where they are used
/// (tools that plot fields follow no `$ref`); a type that contains itself is
/// left open (`{}`) where it recurs.
pub fn json_schema(shape: &TypeShape, title: &str) -> Value {
    let mut s = schema(shape, &shape.root, &mut BTreeSet::new());
    if let Value::Object(m) = &mut s {
        m.insert(
            "$schema".into(),
            json!("https://json-schema.org/draft/2020-12/schema"),
        );
        m.insert("title".into(), json!(title));
    }
    s
}

fn schema<'a>(shape: &'a TypeShape, f: &'a Format, seen: &mut BTreeSet<&'a str>) -> Value {
    match f {
        Format::Unit => json!({"type": "null"}),
        Format::Bool => json!({"type": "boolean"}),
        Format::U8 | Format::U16 | Format::U32 | Format::U64 => {
            json!({"type": "integer", "minimum": 0})
        }
        Format::I8 | Format::I16 | Format::I32 | Format::I64 => json!({"type": "integer"}),
        Format::U128 | Format::I128 => json!({"type": ["integer", "string"]}),
        // Non-finite values are written as null.
        Format::F32 | Format::F64 => json!({"type": ["number", "null"]}),
        Format::Char | Format::Str => json!({"type": "string"}),
        Format::Bytes => {
            json!({"type": "array", "items": {"type": "integer", "minimum": 0, "maximum": 255}})
        }
        Format::Option(inner) => {
            json!({"anyOf": [schema(shape, inner, seen), {"type": "null"}]})
        }
        Format::Seq(inner) => json!({"type": "array", "items": schema(shape, inner, seen)}),
        Format::Map { value, .. } => {
            json!({"type": "object", "additionalProperties": schema(shape, value, seen)})
        }
        Format::Tuple(items) => tuple(shape, items, seen),
        Format::TupleArray { content, size } => json!({
            "type": "array",
            "items": schema(shape, content, seen),
            "minItems": size,
            "maxItems": size,
        }),
        Format::TypeName(name) => match shape.registry.get(name) {
            Some(c) if seen.insert(name) => {
                let s = container_schema(shape, c, seen);
                seen.remove(name.as_str());
                s
            }
            _ => json!({}),
        },
        Format::Variable(_) => json!({}),
    }
}

fn container_schema<'a>(
    shape: &'a TypeShape,
    c: &'a ContainerFormat,
    seen: &mut BTreeSet<&'a str>,
) -> Value {
    match c {
        ContainerFormat::UnitStruct => json!({"type": "null"}),
        ContainerFormat::NewTypeStruct(f) => schema(shape, f, seen),
        ContainerFormat::TupleStruct(fs) => tuple(shape, fs, seen),
        ContainerFormat::Struct(fields) => object(shape, fields, seen),
        ContainerFormat::Enum(variants) => {
            let one_of: Vec<Value> = variants
                .values()
                .map(|v| {
                    let body = match &v.value {
                        VariantFormat::Unit => return json!({"const": v.name}),
                        VariantFormat::NewType(f) => schema(shape, f, seen),
                        VariantFormat::Tuple(fs) => tuple(shape, fs, seen),
                        VariantFormat::Struct(fields) => object(shape, fields, seen),
                        VariantFormat::Variable(_) => json!({}),
                    };
                    json!({
                        "type": "object",
                        "properties": {v.name.clone(): body},
                        "required": [v.name],
                        "additionalProperties": false,
                    })
                })
                .collect();
            json!({"oneOf": one_of})
        }
    }
}

fn tuple<'a>(shape: &'a TypeShape, items: &'a [Format], seen: &mut BTreeSet<&'a str>) -> Value {
    json!({
        "type": "array",
        "prefixItems": items.iter().map(|f| schema(shape, f, seen)).collect::<Vec<_>>(),
        "minItems": items.len(),
        "maxItems": items.len(),
    })
}

fn object<'a>(
    shape: &'a TypeShape,
    fields: &'a [Named<Format>],
    seen: &mut BTreeSet<&'a str>,
) -> Value {
    let mut props = Map::new();
    for f in fields {
        props.insert(f.name.clone(), schema(shape, &f.value, seen));
    }
    json!({
        "type": "object",
        "properties": props,
        "required": fields.iter().map(|f| f.name.as_str()).collect::<Vec<_>>(),
    })
}

#[cfg(test)]
pub(crate) mod tests;
