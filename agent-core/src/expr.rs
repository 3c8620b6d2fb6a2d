//! Boolean expressions over named predicates: initial conditions on FSM arcs and
//! terminal conditions of behaviours (`new_plan && !ready`).
//!
//! The same parser serves the runtime FSM builder and the spec checker, so a
//! condition means the same thing in a RON file and in Rust code.
//!
//! Grammar (whitespace is free; `&&` binds tighter than `||`):
//!
//! ```text
//! or    := and ( "||" and )*
//! and   := unary ( "&&" unary )*
//! unary := "!" unary | atom
//! atom  := "true" | "false" | IDENT | "(" or ")"
//! IDENT := [A-Za-z_][A-Za-z0-9_]*
//! ```
//!
//! `(` and `!` nest at most [`MAX_DEPTH`] deep: the parser, the evaluation and
//! every walk over an expression recurse, and a condition of 20,000 nested
//! parentheses would overflow the stack. Deeper is a syntax error, never a crash.

use std::fmt;

/// How deeply `(` and `!` may nest in a condition.
pub const MAX_DEPTH: usize = 64;

/// A Boolean expression whose atoms are `A` (names when parsed, indices once resolved).
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub enum Expr<A = String> {
    /// `true` or `false`.
    Const(bool),
    /// A named predicate.
    Atom(A),
    /// `!e`
    Not(Box<Expr<A>>),
    /// `e1 && e2 && ...` (at least two operands).
    And(Vec<Expr<A>>),
    /// `e1 || e2 || ...` (at least two operands).
    Or(Vec<Expr<A>>),
}

/// A syntax error in an expression, with the byte offset where it was found.
/// Displayed with the condition (at most 60 characters of it on either side of
/// the offset).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{message} at byte {offset} of `{}`", excerpt(source_text, *offset))]
pub struct ExprError {
    /// Byte offset into the expression text.
    pub offset: usize,
    /// Length in bytes of the offending token (at least 1, except at end of input).
    pub len: usize,
    /// What is wrong.
    pub message: String,
    /// The whole expression text.
    pub source_text: String,
}

/// Up to 60 characters of `text` on either side of byte `at`, with `…` where cut.
fn excerpt(text: &str, at: usize) -> String {
    let at = (0..=at.min(text.len()))
        .rev()
        .find(|&i| text.is_char_boundary(i))
        .unwrap_or(0);
    let before: Vec<char> = text[..at].chars().rev().take(61).collect();
    let after: Vec<char> = text[at..].chars().take(61).collect();
    let mut out = String::new();
    if before.len() > 60 {
        out.push('…');
    }
    out.extend(before.iter().take(60).rev());
    out.extend(after.iter().take(60));
    if after.len() > 60 {
        out.push('…');
    }
    out
}

impl Expr<String> {
    /// Parse an expression.
    ///
    /// ```
    /// use agent_core::Expr;
    /// let e = Expr::parse("new_plan && !ready").unwrap();
    /// assert_eq!(e.to_string(), "new_plan && !ready");
    /// assert!(e.eval(&mut |p: &String| p == "new_plan"));
    /// ```
    pub fn parse(text: &str) -> Result<Expr<String>, ExprError> {
        let mut p = Parser {
            text,
            bytes: text.as_bytes(),
            pos: 0,
            depth: 0,
        };
        p.skip_ws();
        let e = p.or()?;
        p.skip_ws();
        if p.pos < p.bytes.len() {
            return Err(p.error("expected `&&`, `||` or the end of the condition"));
        }
        Ok(e)
    }
}

impl<A> Expr<A> {
    /// Evaluate with `atom` giving the value of each atom.
    #[inline]
    pub fn eval(&self, atom: &mut impl FnMut(&A) -> bool) -> bool {
        match self {
            Expr::Const(b) => *b,
            Expr::Atom(a) => atom(a),
            Expr::Not(e) => !e.eval(atom),
            Expr::And(es) => es.iter().all(|e| e.eval(atom)),
            Expr::Or(es) => es.iter().any(|e| e.eval(atom)),
        }
    }

    /// The same expression with every atom mapped by `f` (stops at the first error).
    pub fn try_map<B, E>(&self, f: &mut impl FnMut(&A) -> Result<B, E>) -> Result<Expr<B>, E> {
        Ok(match self {
            Expr::Const(b) => Expr::Const(*b),
            Expr::Atom(a) => Expr::Atom(f(a)?),
            Expr::Not(e) => Expr::Not(Box::new(e.try_map(f)?)),
            Expr::And(es) => Expr::And(es.iter().map(|e| e.try_map(f)).collect::<Result<_, _>>()?),
            Expr::Or(es) => Expr::Or(es.iter().map(|e| e.try_map(f)).collect::<Result<_, _>>()?),
        })
    }

    /// Visit every atom, left to right (with repetitions).
    pub fn for_each_atom<'a>(&'a self, f: &mut impl FnMut(&'a A)) {
        match self {
            Expr::Const(_) => {}
            Expr::Atom(a) => f(a),
            Expr::Not(e) => e.for_each_atom(f),
            Expr::And(es) | Expr::Or(es) => es.iter().for_each(|e| e.for_each_atom(f)),
        }
    }

    /// Whether the expression is the literal `false` (a condition that never holds).
    pub fn is_const_false(&self) -> bool {
        matches!(self, Expr::Const(false))
    }

    /// The negation, without a double negation: `!e` for most `e`, but `x` for
    /// `!x` and `false` for `true` (how a while-behaviour's terminal condition
    /// reads as the condition it runs while).
    pub fn negated(self) -> Expr<A> {
        match self {
            Expr::Not(inner) => *inner,
            Expr::Const(b) => Expr::Const(!b),
            e => Expr::Not(Box::new(e)),
        }
    }
}

impl<A: fmt::Display> Expr<A> {
    fn fmt_prec(&self, f: &mut fmt::Formatter<'_>, prec: u8) -> fmt::Result {
        // prec: 0 = or, 1 = and, 2 = unary
        match self {
            Expr::Const(b) => write!(f, "{b}"),
            Expr::Atom(a) => write!(f, "{a}"),
            Expr::Not(e) => {
                f.write_str("!")?;
                e.fmt_prec(f, 2)
            }
            Expr::And(es) | Expr::Or(es) => {
                let (op, my) = if matches!(self, Expr::And(_)) {
                    (" && ", 1)
                } else {
                    (" || ", 0)
                };
                if prec > my {
                    f.write_str("(")?;
                }
                for (i, e) in es.iter().enumerate() {
                    if i > 0 {
                        f.write_str(op)?;
                    }
                    e.fmt_prec(f, my + 1)?;
                }
                if prec > my {
                    f.write_str(")")?;
                }
                Ok(())
            }
        }
    }
}

impl<A: fmt::Display> fmt::Display for Expr<A> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.fmt_prec(f, 0)
    }
}

struct Parser<'a> {
    text: &'a str,
    bytes: &'a [u8],
    pos: usize,
    /// `(` and `!` open around the current position.
    depth: usize,
}

impl Parser<'_> {
    fn error(&self, message: &str) -> ExprError {
        let len = match self.bytes.get(self.pos) {
            None => 0,
            Some(b) if b.is_ascii_alphanumeric() || *b == b'_' => self.bytes[self.pos..]
                .iter()
                .take_while(|b| b.is_ascii_alphanumeric() || **b == b'_')
                .count(),
            Some(_) => self.text[self.pos..]
                .chars()
                .next()
                .map_or(1, char::len_utf8),
        };
        ExprError {
            offset: self.pos,
            len,
            message: message.to_owned(),
            source_text: self.text.to_owned(),
        }
    }

    fn skip_ws(&mut self) {
        while self
            .bytes
            .get(self.pos)
            .is_some_and(u8::is_ascii_whitespace)
        {
            self.pos += 1;
        }
    }

    fn eat(&mut self, token: &str) -> bool {
        self.skip_ws();
        if self.text[self.pos..].starts_with(token) {
            self.pos += token.len();
            true
        } else {
            false
        }
    }

    fn or(&mut self) -> Result<Expr, ExprError> {
        let mut items = vec![self.and()?];
        while self.eat("||") {
            items.push(self.and()?);
        }
        Ok(if items.len() == 1 {
            items.swap_remove(0)
        } else {
            Expr::Or(items)
        })
    }

    fn and(&mut self) -> Result<Expr, ExprError> {
        let mut items = vec![self.unary()?];
        while self.eat("&&") {
            items.push(self.unary()?);
        }
        Ok(if items.len() == 1 {
            items.swap_remove(0)
        } else {
            Expr::And(items)
        })
    }

    /// One level deeper (a `(` or a `!` at the current position).
    fn deeper(&mut self) -> Result<(), ExprError> {
        if self.depth >= MAX_DEPTH {
            return Err(self.error(&format!(
                "`(` and `!` nest more than {MAX_DEPTH} levels deep here"
            )));
        }
        self.depth += 1;
        Ok(())
    }

    fn unary(&mut self) -> Result<Expr, ExprError> {
        self.skip_ws();
        if self.bytes.get(self.pos) == Some(&b'!') {
            self.deeper()?;
            self.pos += 1;
            let e = Expr::Not(Box::new(self.unary()?));
            self.depth -= 1;
            return Ok(e);
        }
        self.atom()
    }

    fn atom(&mut self) -> Result<Expr, ExprError> {
        self.skip_ws();
        match self.bytes.get(self.pos) {
            Some(b'(') => {
                self.deeper()?;
                self.pos += 1;
                let e = self.or()?;
                if !self.eat(")") {
                    return Err(self.error("expected `)`"));
                }
                self.depth -= 1;
                Ok(e)
            }
            Some(b) if b.is_ascii_alphabetic() || *b == b'_' => {
                let start = self.pos;
                while self
                    .bytes
                    .get(self.pos)
                    .is_some_and(|b| b.is_ascii_alphanumeric() || *b == b'_')
                {
                    self.pos += 1;
                }
                Ok(match &self.text[start..self.pos] {
                    "true" => Expr::Const(true),
                    "false" => Expr::Const(false),
                    name => Expr::Atom(name.to_owned()),
                })
            }
            None => Err(self.error("unexpected end of the condition, expected a predicate")),
            Some(_) => Err(self.error("expected a predicate name, `!`, `(`, `true` or `false`")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(s: &str) -> Expr {
        Expr::parse(s).unwrap()
    }

    #[test]
    fn negation_reads_without_double_negation() {
        for (s, negated) in [
            ("blocked", "!blocked"),
            ("!blocked", "blocked"),
            ("!(a && b)", "a && b"),
            ("a || b", "!(a || b)"),
            ("true", "false"),
        ] {
            assert_eq!(p(s).negated().to_string(), negated, "negation of {s}");
        }
    }

    #[test]
    fn precedence_and_display_round_trip() {
        for s in [
            "a",
            "!a",
            "a && b",
            "a || b && c",
            "(a || b) && c",
            "!(a && b) || !c",
            "true",
            "a && !(b || false)",
        ] {
            assert_eq!(p(s).to_string(), s, "round trip of {s}");
        }
        assert_eq!(p("  a&&b ||c ").to_string(), "a && b || c");
        assert_eq!(
            p("a || b && c"),
            Expr::Or(vec![
                Expr::Atom("a".into()),
                Expr::And(vec![Expr::Atom("b".into()), Expr::Atom("c".into())])
            ])
        );
    }

    #[test]
    fn evaluation_follows_boolean_logic() {
        let e = p("new_plan && !ready || done");
        let eval = |np: bool, r: bool, d: bool| {
            e.eval(&mut |a: &String| match a.as_str() {
                "new_plan" => np,
                "ready" => r,
                _ => d,
            })
        };
        for bits in 0..8u8 {
            let (np, r, d) = (bits & 1 != 0, bits & 2 != 0, bits & 4 != 0);
            assert_eq!(eval(np, r, d), (np && !r) || d);
        }
    }

    #[test]
    fn syntax_errors_point_at_the_token() {
        let e = Expr::parse("a && && b").unwrap_err();
        assert_eq!((e.offset, e.len), (5, 1));
        let e = Expr::parse("a && (b").unwrap_err();
        assert_eq!(e.offset, 7);
        assert!(e.message.contains("`)`"));
        let e = Expr::parse("a b").unwrap_err();
        assert_eq!((e.offset, e.len), (2, 1));
        let e = Expr::parse("").unwrap_err();
        assert_eq!(e.offset, 0);
        let e = Expr::parse("a & b").unwrap_err();
        assert_eq!(e.offset, 2);
        assert!(Expr::parse("ä").is_err());
    }

    #[test]
    fn nesting_is_bounded_not_a_stack_overflow() {
        let deep = |n: usize| format!("{}a{}", "(".repeat(n), ")".repeat(n));
        assert!(Expr::parse(&deep(MAX_DEPTH)).is_ok());
        for text in [
            deep(MAX_DEPTH + 1),
            deep(20_000),
            format!("{}a", "!".repeat(50_000)),
        ] {
            let e = Expr::parse(&text).unwrap_err();
            assert!(
                e.message.contains("nest more than 64 levels"),
                "{}",
                e.message
            );
            assert_eq!(e.offset, MAX_DEPTH, "at the first level too many");
        }
        // Long flat chains are fine: they do not nest.
        let flat = vec!["a"; 100_000].join(" && ");
        assert!(Expr::parse(&flat).is_ok());
    }

    #[test]
    fn mapping_atoms_resolves_names() {
        let names = ["x", "y"];
        let e = p("x && !y");
        let r: Expr<usize> = e
            .try_map(&mut |a: &String| names.iter().position(|n| n == a).ok_or(a.clone()))
            .unwrap();
        assert_eq!(r.to_string(), "0 && !1");
        let err = p("x && z")
            .try_map(&mut |a: &String| names.iter().position(|n| n == a).ok_or(a.clone()))
            .unwrap_err();
        assert_eq!(err, "z");
    }
}
