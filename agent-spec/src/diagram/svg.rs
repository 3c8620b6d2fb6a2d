//! A small SVG writer and a layered graph layout, so diagrams need no Graphviz.
//!
//! Text is set in a monospace font so that box widths follow from character counts;
//! every number is written with one decimal, so the output is byte-stable.

use std::fmt::Write as _;

use super::geometry::{self, Owner, Path, Point, Rect, Scene};

/// Font size of labels \[px\].
pub(crate) const FONT: f64 = 12.0;
/// Width of one character of the monospace font at [`FONT`] \[px\].
pub(crate) const CHAR_W: f64 = 7.3;
/// Height of one line of text \[px\].
pub(crate) const LINE_H: f64 = 15.0;
/// Padding inside boxes \[px\].
pub(crate) const PAD: f64 = 8.0;
/// Margin around a drawing \[px\].
pub(crate) const MARGIN: f64 = 20.0;
/// Stroke and text colour.
pub(crate) const INK: &str = "#222222";
/// Fill of boxes.
pub(crate) const BOX_FILL: &str = "#f4f6fb";
/// Fill of group frames (agents, behaviours).
pub(crate) const FRAME_FILL: &str = "#fbfbf4";
/// Colour of edges and their labels.
pub(crate) const EDGE: &str = "#3b5b92";

/// Escape text for XML.
pub(crate) fn esc(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// Width of a text line \[px\].
pub(crate) fn text_w(s: &str) -> f64 {
    s.chars().count() as f64 * CHAR_W
}

/// Height of an edge label (its white background) \[px\].
pub(crate) const LABEL_H: f64 = 16.0;

/// Width of an edge label of `s` (its white background) \[px\].
pub(crate) fn label_w(s: &str) -> f64 {
    text_w(s) + 6.0
}

/// Height of the glyphs above the baseline \[px\].
pub(crate) const ASCENT: f64 = 0.8 * FONT;
/// Depth of the glyphs below the baseline \[px\].
pub(crate) const DESCENT: f64 = 0.25 * FONT;

/// The extent of a line of text whose baseline starts at `(x, y)`.
pub(crate) fn text_rect(x: f64, y: f64, s: &str) -> Rect {
    Rect::new(x, y - ASCENT, text_w(s), ASCENT + DESCENT)
}

/// A box with lines of text; the first line is the title.
#[derive(Clone, Debug)]
pub(crate) struct Boxed {
    pub(crate) lines: Vec<String>,
    pub(crate) x: f64,
    pub(crate) y: f64,
    pub(crate) w: f64,
    pub(crate) h: f64,
    /// Draw a double border (final FSM nodes).
    pub(crate) double: bool,
    /// Rounded corners.
    pub(crate) rounded: bool,
}

impl Boxed {
    pub(crate) fn new(lines: Vec<String>) -> Boxed {
        let w = lines.iter().map(|l| text_w(l)).fold(0.0, f64::max) + 2.0 * PAD;
        let h = lines.len() as f64 * LINE_H + 2.0 * PAD - 3.0;
        Boxed {
            lines,
            x: 0.0,
            y: 0.0,
            w: w.max(40.0),
            h,
            double: false,
            rounded: true,
        }
    }

    pub(crate) fn cx(&self) -> f64 {
        self.x + self.w / 2.0
    }
}

/// An SVG document under construction.
pub(crate) struct Svg {
    body: String,
    scene: Scene,
}

impl Svg {
    pub(crate) fn new() -> Svg {
        Svg {
            body: String::new(),
            scene: Scene::default(),
        }
    }

    fn text(&mut self, x: f64, y: f64, attrs: &str, text: &str, owner: Owner) {
        let _ = writeln!(
            self.body,
            r#"<text x="{x:.1}" y="{y:.1}"{attrs}>{}</text>"#,
            esc(text)
        );
        self.scene.labels.push(geometry::Label {
            text: text.to_owned(),
            at: Point::new(x, y),
            rect: text_rect(x, y, text),
            owner,
        });
    }

    /// The document and what it placed.
    pub(crate) fn finish(self, w: f64, h: f64, title: &str) -> (String, Scene) {
        let text = self.finish_text(w, h, title);
        let mut scene = self.scene;
        scene.width = w;
        scene.height = h;
        (text, scene)
    }

    fn finish_text(&self, w: f64, h: f64, title: &str) -> String {
        let mut out = String::new();
        let _ = writeln!(
            out,
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w:.1}" height="{h:.1}" viewBox="0 0 {w:.1} {h:.1}" font-family="monospace" font-size="{FONT:.1}">"#
        );
        let _ = writeln!(out, "<title>{}</title>", esc(title));
        let _ = writeln!(
            out,
            r#"<defs><marker id="arrow" viewBox="0 0 10 10" refX="10" refY="5" markerWidth="8" markerHeight="8" orient="auto-start-reverse"><path d="M0,0 L10,5 L0,10 z" fill="{EDGE}"/></marker></defs>"#
        );
        let _ = writeln!(
            out,
            r#"<rect x="0.0" y="0.0" width="{w:.1}" height="{h:.1}" fill="white"/>"#
        );
        out.push_str(&self.body);
        out.push_str("</svg>\n");
        out
    }

    /// The scene index the next box will have.
    pub(crate) fn next_box(&self) -> usize {
        self.scene.boxes.len()
    }

    /// A dashed frame with a title; returns its index in the scene.
    pub(crate) fn frame(&mut self, x: f64, y: f64, w: f64, h: f64, title: &str) -> usize {
        let _ = writeln!(
            self.body,
            r#"<rect x="{x:.1}" y="{y:.1}" width="{w:.1}" height="{h:.1}" rx="6.0" fill="{FRAME_FILL}" stroke="{INK}" stroke-dasharray="4 3"/>"#
        );
        let i = self.scene.frames.len();
        self.scene.frames.push(geometry::Frame {
            rect: Rect::new(x, y, w, h),
        });
        let attrs = format!(r#" fill="{INK}" font-weight="bold""#);
        self.text(x + PAD, y + LINE_H, &attrs, title, Owner::Frame(i));
        i
    }

    /// A titled frame at the left margin from `y` down, around content that
    /// starts at `top` and ends at `right` and `bottom` (with [`PAD`] to spare),
    /// at least as wide as its title: its index in the scene, width and height.
    pub(crate) fn frame_around(
        &mut self,
        (y, top): (f64, f64),
        (right, bottom): (f64, f64),
        title: &str,
    ) -> (usize, f64, f64) {
        let right = right.max(MARGIN + PAD + text_w(title)) + PAD;
        let w = right - MARGIN;
        let h = bottom.max(top) + PAD - y;
        (self.frame(MARGIN, y, w, h, title), w, h)
    }

    /// A box in `frame`; returns its index in the scene.
    pub(crate) fn boxed(&mut self, b: &Boxed, frame: Option<usize>) -> usize {
        let id = self.scene.boxes.len();
        self.scene.boxes.push(geometry::BoxShape {
            rect: Rect::new(b.x, b.y, b.w, b.h),
            frame,
        });
        let rx: f64 = if b.rounded { 8.0 } else { 0.0 };
        let _ = writeln!(
            self.body,
            r#"<rect x="{:.1}" y="{:.1}" width="{:.1}" height="{:.1}" rx="{rx:.1}" fill="{BOX_FILL}" stroke="{INK}"/>"#,
            b.x, b.y, b.w, b.h
        );
        if b.double {
            let _ = writeln!(
                self.body,
                r#"<rect x="{:.1}" y="{:.1}" width="{:.1}" height="{:.1}" rx="{:.1}" fill="none" stroke="{INK}"/>"#,
                b.x + 3.0,
                b.y + 3.0,
                b.w - 6.0,
                b.h - 6.0,
                (rx - 3.0).max(0.0)
            );
        }
        for (i, line) in b.lines.iter().enumerate() {
            let weight = if i == 0 { r#" font-weight="bold""# } else { "" };
            let attrs = format!(r#" fill="{INK}"{weight}"#);
            self.text(
                b.x + PAD,
                b.y + PAD + (i as f64 + 0.8) * LINE_H,
                &attrs,
                line,
                Owner::Box(id),
            );
        }
        id
    }

    pub(crate) fn dot(&mut self, x: f64, y: f64, r: f64) {
        let _ = writeln!(
            self.body,
            r#"<circle cx="{x:.1}" cy="{y:.1}" r="{r:.1}" fill="{INK}"/>"#
        );
    }

    /// A path with an arrow head, from box `from` to box `to` (scene indices), and an
    /// optional label.
    pub(crate) fn edge(
        &mut self,
        path: &Path,
        label: Option<(&str, &LabelAt)>,
        ends: (Option<usize>, Option<usize>),
        frame: Option<usize>,
    ) {
        let _ = writeln!(
            self.body,
            r#"<path d="{}" fill="none" stroke="{EDGE}" marker-end="url(#arrow)"/>"#,
            path.to_d()
        );
        let id = self.scene.edges.len();
        self.scene.edges.push(geometry::Edge {
            path: path.clone(),
            from: ends.0,
            to: ends.1,
            label: None,
            frame,
        });
        if let Some((text, at)) = label.filter(|(t, _)| !t.is_empty()) {
            let w = label_w(text);
            let left = at.x;
            let _ = writeln!(
                self.body,
                r#"<rect x="{left:.1}" y="{:.1}" width="{w:.1}" height="{LABEL_H:.1}" fill="white" fill-opacity="0.85"/>"#,
                at.y - LABEL_H / 2.0,
            );
            let back = Rect::new(left, at.y - LABEL_H / 2.0, w, LABEL_H);
            let attrs = format!(r#" fill="{EDGE}""#);
            self.text(left + 3.0, at.y + 4.0, &attrs, text, Owner::Edge(id));
            let n = self.scene.labels.len() - 1;
            let l = &mut self.scene.labels[n];
            l.rect = l.rect.union(&back);
            self.scene.edges[id].label = Some(n);
        }
    }
}

/// Where an edge label goes: the left end of its white background, and the middle
/// of its height.
#[derive(Clone, Copy, Debug)]
pub(crate) struct LabelAt {
    pub(crate) x: f64,
    pub(crate) y: f64,
}

impl LabelAt {
    /// The right end of a label of `text` placed here.
    pub(crate) fn right(&self, text: &str) -> f64 {
        self.x + label_w(text)
    }
}
