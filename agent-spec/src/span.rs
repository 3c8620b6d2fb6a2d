//! A side index from positions in the spec to byte ranges of the RON text.
//!
//! `ron` deserialises the spec with serde and keeps no positions, so the loader parses
//! the same text a second time into a tree of spans, used only to point diagnostics at
//! the right token. The parser accepts the RON that `ron` accepted (structs, tuples,
//! enum variants, lists, maps, strings, raw strings, chars, numbers, comments,
//! extensions); on anything else it stops, and diagnostics fall back to coarser spans.

use std::ops::Range;

/// A node of the span tree.
#[derive(Clone, Debug, PartialEq)]
pub struct SNode {
    /// Byte range of the whole value.
    pub span: Range<usize>,
    /// What it is.
    pub kind: SKind,
}

/// The shape of a value.
#[derive(Clone, Debug, PartialEq)]
pub enum SKind {
    /// `Name(field: value, ...)` or `(field: value, ...)`.
    Struct {
        /// Struct name, if written.
        name: Option<String>,
        /// Fields in order.
        fields: Vec<SField>,
    },
    /// `Name(value, ...)`, `(value, ...)`, `Some(value)`.
    Tuple {
        /// Variant or struct name, if written.
        name: Option<String>,
        /// Items in order.
        items: Vec<SNode>,
    },
    /// `[value, ...]`
    List(Vec<SNode>),
    /// `{key: value, ...}`
    Map(Vec<(SNode, SNode)>),
    /// A string; `content` is the range between the quotes, `verbatim` whether the
    /// content bytes equal the decoded string (no escapes).
    Str {
        /// Decoded value.
        value: String,
        /// Byte range between the delimiters.
        content: Range<usize>,
        /// No escapes: offsets into `value` are offsets into the text.
        verbatim: bool,
    },
    /// Numbers, booleans, chars, unit variants, `()`.
    Atom,
}

/// A field of a struct.
#[derive(Clone, Debug, PartialEq)]
pub struct SField {
    /// Field name.
    pub key: String,
    /// Byte range of the name.
    pub key_span: Range<usize>,
    /// The value.
    pub value: SNode,
}

/// One step of a path into the tree.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Seg<'a> {
    /// A struct field.
    Field(&'a str),
    /// A list or tuple item.
    Item(usize),
}

impl SNode {
    /// The node at `path`, looking through `Some(...)`.
    pub fn at(&self, path: &[Seg<'_>]) -> Option<&SNode> {
        let mut node = self;
        for seg in path {
            node = node.unwrap_some();
            node = match (seg, &node.kind) {
                (Seg::Field(f), SKind::Struct { fields, .. }) => {
                    &fields.iter().find(|x| x.key == *f)?.value
                }
                (Seg::Item(i), SKind::List(items) | SKind::Tuple { items, .. }) => items.get(*i)?,
                _ => return None,
            };
        }
        Some(node.unwrap_some())
    }

    /// The key span of field `path.last()` (the field's name), if it is a field.
    pub fn key_at(&self, path: &[Seg<'_>]) -> Option<Range<usize>> {
        let (last, parent) = path.split_last()?;
        let Seg::Field(f) = last else { return None };
        match &self.at(parent)?.kind {
            SKind::Struct { fields, .. } => fields
                .iter()
                .find(|x| x.key == *f)
                .map(|x| x.key_span.clone()),
            _ => None,
        }
    }

    fn unwrap_some(&self) -> &SNode {
        match &self.kind {
            SKind::Tuple {
                name: Some(n),
                items,
            } if n == "Some" && items.len() == 1 => &items[0],
            _ => self,
        }
    }

    /// For a string, the range of its content; otherwise the whole span.
    pub fn content_span(&self) -> Range<usize> {
        match &self.kind {
            SKind::Str { content, .. } => content.clone(),
            _ => self.span.clone(),
        }
    }

    /// For a string without escapes, the text range of bytes `r` of its value.
    pub fn sub_span(&self, r: Range<usize>) -> Range<usize> {
        match &self.kind {
            SKind::Str {
                content, verbatim, ..
            } if *verbatim => {
                let start = (content.start + r.start).min(content.end);
                start..(content.start + r.end).clamp(start, content.end)
            }
            _ => self.content_span(),
        }
    }
}

/// Parse `text` into a span tree; `None` if it is not RON this parser understands.
pub fn parse(text: &str) -> Option<SNode> {
    let mut p = P {
        s: text.as_bytes(),
        text,
        i: 0,
        depth: 0,
    };
    p.ws();
    // Extensions: `#![enable(...)]`.
    while p.s.get(p.i) == Some(&b'#') {
        p.skip_attribute()?;
        p.ws();
    }
    let v = p.value()?;
    p.ws();
    (p.i == p.s.len()).then_some(v)
}

struct P<'a> {
    s: &'a [u8],
    text: &'a str,
    i: usize,
    depth: usize,
}

const MAX_DEPTH: usize = 128;

impl P<'_> {
    fn peek(&self) -> Option<u8> {
        self.s.get(self.i).copied()
    }

    fn rest(&self) -> &[u8] {
        self.s.get(self.i..).unwrap_or(&[])
    }

    fn ws(&mut self) {
        loop {
            while self.peek().is_some_and(|c| c.is_ascii_whitespace()) {
                self.i += 1;
            }
            if self.rest().starts_with(b"//") {
                while self.peek().is_some_and(|c| c != b'\n') {
                    self.i += 1;
                }
            } else if self.rest().starts_with(b"/*") {
                let mut level = 0usize;
                while self.i < self.s.len() {
                    if self.rest().starts_with(b"/*") {
                        level += 1;
                        self.i += 2;
                    } else if self.rest().starts_with(b"*/") {
                        level -= 1;
                        self.i += 2;
                        if level == 0 {
                            break;
                        }
                    } else {
                        self.i += 1;
                    }
                }
            } else {
                return;
            }
        }
    }

    fn skip_attribute(&mut self) -> Option<()> {
        // `#![...]`, brackets balanced.
        self.i += 1;
        if self.peek() == Some(b'!') {
            self.i += 1;
        }
        if self.peek() != Some(b'[') {
            return None;
        }
        let mut level = 0;
        while let Some(c) = self.peek() {
            self.i += 1;
            match c {
                b'[' => level += 1,
                b']' => {
                    level -= 1;
                    if level == 0 {
                        return Some(());
                    }
                }
                _ => {}
            }
        }
        None
    }

    fn ident(&mut self) -> Option<String> {
        let start = self.i;
        if self.rest().starts_with(b"r#") {
            self.i += 2;
        }
        let body = self.i;
        while self
            .peek()
            .is_some_and(|c| c.is_ascii_alphanumeric() || c == b'_')
        {
            self.i += 1;
        }
        if self.i == body {
            self.i = start;
            return None;
        }
        Some(self.text[body..self.i].to_owned())
    }

    fn value(&mut self) -> Option<SNode> {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            return None;
        }
        let v = self.value_inner();
        self.depth -= 1;
        v
    }

    fn value_inner(&mut self) -> Option<SNode> {
        self.ws();
        let start = self.i;
        match self.peek()? {
            b'"' => self.string(start, 0),
            b'r' if matches!(self.s.get(self.i + 1), Some(b'"' | b'#')) => {
                let mut hashes = 0;
                self.i += 1;
                while self.peek() == Some(b'#') {
                    hashes += 1;
                    self.i += 1;
                }
                self.string(start, hashes)
            }
            b'b' if self.s.get(self.i + 1) == Some(&b'"') => {
                self.i += 1;
                self.string(start, 0)
            }
            b'\'' => {
                self.i += 1;
                while let Some(c) = self.peek() {
                    self.i += 1;
                    match c {
                        b'\\' => self.i += 1,
                        b'\'' => break,
                        _ => {}
                    }
                }
                Some(self.atom(start))
            }
            b'[' => {
                self.i += 1;
                let items = self.seq(b']')?;
                Some(SNode {
                    span: start..self.i,
                    kind: SKind::List(items),
                })
            }
            b'{' => {
                self.i += 1;
                let mut entries = Vec::new();
                loop {
                    self.ws();
                    if self.peek()? == b'}' {
                        self.i += 1;
                        break;
                    }
                    let k = self.value()?;
                    self.ws();
                    if self.peek()? != b':' {
                        return None;
                    }
                    self.i += 1;
                    let v = self.value()?;
                    entries.push((k, v));
                    self.ws();
                    if self.peek() == Some(b',') {
                        self.i += 1;
                    }
                }
                Some(SNode {
                    span: start..self.i,
                    kind: SKind::Map(entries),
                })
            }
            b'(' => self.parens(start, None),
            c if c.is_ascii_alphabetic() || c == b'_' => {
                let name = self.ident()?;
                let after = self.i;
                self.ws();
                if self.peek() == Some(b'(') {
                    self.parens(start, Some(name))
                } else {
                    self.i = after;
                    Some(self.atom(start))
                }
            }
            c if c.is_ascii_digit() || matches!(c, b'-' | b'+' | b'.') => {
                while self.peek().is_some_and(|c| {
                    c.is_ascii_alphanumeric() || matches!(c, b'.' | b'_' | b'-' | b'+')
                }) {
                    self.i += 1;
                }
                Some(self.atom(start))
            }
            _ => None,
        }
    }

    fn atom(&self, start: usize) -> SNode {
        SNode {
            span: start..self.i,
            kind: SKind::Atom,
        }
    }

    /// A string whose opening quote is at `self.i`, with `hashes` raw-string hashes.
    fn string(&mut self, start: usize, hashes: usize) -> Option<SNode> {
        if self.peek()? != b'"' {
            return None;
        }
        self.i += 1;
        let content_start = self.i;
        let raw = start < content_start - 1 && self.s[start] == b'r';
        let mut value = String::new();
        let mut verbatim = true;
        loop {
            let c = self.peek()?;
            if c == b'"' {
                let closes = (0..hashes).all(|k| self.s.get(self.i + 1 + k) == Some(&b'#'));
                if closes {
                    let content = content_start..self.i;
                    self.i += 1 + hashes;
                    if verbatim {
                        value = self.text[content.clone()].to_owned();
                    }
                    return Some(SNode {
                        span: start..self.i,
                        kind: SKind::Str {
                            value,
                            content,
                            verbatim,
                        },
                    });
                }
            }
            if c == b'\\' && !raw {
                verbatim = false;
                value.push_str(&self.text[content_start..self.i]);
                // Keep it simple: the decoded value of an escaped string is only used
                // for lookups, which use the spec's own (serde-decoded) strings.
                self.i += 2;
                continue;
            }
            self.i += 1;
        }
    }

    fn seq(&mut self, close: u8) -> Option<Vec<SNode>> {
        let mut items = Vec::new();
        loop {
            self.ws();
            if self.peek()? == close {
                self.i += 1;
                return Some(items);
            }
            items.push(self.value()?);
            self.ws();
            match self.peek()? {
                b',' => self.i += 1,
                c if c == close => {}
                _ => return None,
            }
        }
    }

    fn parens(&mut self, start: usize, name: Option<String>) -> Option<SNode> {
        self.i += 1; // '('
        self.ws();
        // A struct if the first thing is `ident :` (and not `ident ::`).
        let save = self.i;
        let is_struct = match self.ident() {
            Some(_) => {
                self.ws();
                let colon = self.peek() == Some(b':') && self.s.get(self.i + 1) != Some(&b':');
                self.i = save;
                colon
            }
            None => false,
        };
        if !is_struct {
            let items = self.seq(b')')?;
            return Some(SNode {
                span: start..self.i,
                kind: SKind::Tuple { name, items },
            });
        }
        let mut fields = Vec::new();
        loop {
            self.ws();
            if self.peek()? == b')' {
                self.i += 1;
                break;
            }
            let key = self.ident()?;
            // The name itself (`eads` of `r#eads`): what `key` holds.
            let key_span = self.i - key.len()..self.i;
            self.ws();
            if self.peek()? != b':' {
                return None;
            }
            self.i += 1;
            let value = self.value()?;
            fields.push(SField {
                key,
                key_span,
                value,
            });
            self.ws();
            match self.peek()? {
                b',' => self.i += 1,
                b')' => {}
                _ => return None,
            }
        }
        Some(SNode {
            span: start..self.i,
            kind: SKind::Struct { name, fields },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_raw_field_name_spans_its_name() {
        // Found by the fuzzer: `#` inserted into `reads` made `r#eads`, whose key
        // span covered the `r#` while the key did not.
        let text = "(r#eads: 1)";
        let root = parse(text).unwrap();
        let SKind::Struct { fields, .. } = &root.kind else {
            panic!("{root:?}")
        };
        assert_eq!(fields[0].key, "eads");
        assert_eq!(&text[fields[0].key_span.clone()], "eads");
    }

    #[test]
    fn spans_of_nested_values() {
        let text = r##"#![enable(implicit_some)]
// a comment
Spec( /* nested /* block */ */
    name: "rex",
    list: [ (a: 1, b: r#"x"y"#), Queue(4), Some("s\n") ],
    map: { "k": -1.5e3 },
)"##;
        let root = parse(text).expect("parses");
        let name = root.at(&[Seg::Field("name")]).unwrap();
        assert_eq!(&text[name.span.clone()], "\"rex\"");
        assert_eq!(&text[name.content_span()], "rex");
        let b = root
            .at(&[Seg::Field("list"), Seg::Item(0), Seg::Field("b")])
            .unwrap();
        assert_eq!(&text[b.content_span()], "x\"y");
        let q = root.at(&[Seg::Field("list"), Seg::Item(1)]).unwrap();
        assert_eq!(&text[q.span.clone()], "Queue(4)");
        let s = root.at(&[Seg::Field("list"), Seg::Item(2)]).unwrap();
        assert!(
            matches!(
                &s.kind,
                SKind::Str {
                    verbatim: false,
                    ..
                }
            ),
            "{s:?}"
        );
        assert_eq!(
            root.key_at(&[Seg::Field("map")]).map(|r| &text[r]),
            Some("map")
        );
        assert!(root.at(&[Seg::Field("nope")]).is_none());
    }

    #[test]
    fn garbage_gives_none_not_a_panic() {
        for text in [
            "",
            "(",
            "(a: ",
            "[1, 2",
            "\"open",
            "(a: 1 b: 2)",
            "#![x",
            "/* open",
            "r#\"x\"",
            "é",
        ] {
            let _ = parse(text);
        }
        assert!(parse("(a: [1, 2, (3)], b: None)").is_some());
    }
}
