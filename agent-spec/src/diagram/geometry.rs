//! What an SVG drawing placed, as geometry: the boxes, frames, text labels and edge
//! paths, recorded by the writer as it emits them (the same numbers, before they are
//! formatted). Tests check the layout on it (no label over another or over a box, no
//! edge through a box, every edge label on its edge); it is not a stable API.

use std::fmt::Write as _;

/// A point (px).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Point {
    /// Rightwards.
    pub x: f64,
    /// Downwards.
    pub y: f64,
}

impl Point {
    /// The point `(x, y)`.
    pub fn new(x: f64, y: f64) -> Point {
        Point { x, y }
    }
}

/// An axis-aligned rectangle (px).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rect {
    /// Left.
    pub x: f64,
    /// Top.
    pub y: f64,
    /// Width.
    pub w: f64,
    /// Height.
    pub h: f64,
}

impl Rect {
    /// The rectangle with top left `(x, y)` and size `w` × `h`.
    pub fn new(x: f64, y: f64, w: f64, h: f64) -> Rect {
        Rect { x, y, w, h }
    }

    /// Right edge.
    pub fn right(&self) -> f64 {
        self.x + self.w
    }

    /// Bottom edge.
    pub fn bottom(&self) -> f64 {
        self.y + self.h
    }

    /// The rectangle grown by `d` on every side (shrunk if `d` is negative).
    pub fn inflate(&self, d: f64) -> Rect {
        Rect::new(self.x - d, self.y - d, self.w + 2.0 * d, self.h + 2.0 * d)
    }

    /// Whether the two overlap in an area (touching edges do not count).
    pub fn overlaps(&self, o: &Rect) -> bool {
        self.x < o.right() && o.x < self.right() && self.y < o.bottom() && o.y < self.bottom()
    }

    /// Whether `o` lies inside this rectangle (edges included).
    pub fn contains(&self, o: &Rect) -> bool {
        o.x >= self.x && o.y >= self.y && o.right() <= self.right() && o.bottom() <= self.bottom()
    }

    /// Whether `p` lies strictly inside.
    pub fn has_inside(&self, p: Point) -> bool {
        p.x > self.x && p.x < self.right() && p.y > self.y && p.y < self.bottom()
    }

    /// Distance from `p` to the rectangle (0 inside).
    pub fn distance(&self, p: Point) -> f64 {
        let dx = (self.x - p.x).max(p.x - self.right()).max(0.0);
        let dy = (self.y - p.y).max(p.y - self.bottom()).max(0.0);
        dx.hypot(dy)
    }

    /// The smallest rectangle holding both.
    pub fn union(&self, o: &Rect) -> Rect {
        let (x, y) = (self.x.min(o.x), self.y.min(o.y));
        Rect::new(
            x,
            y,
            self.right().max(o.right()) - x,
            self.bottom().max(o.bottom()) - y,
        )
    }
}

/// One piece of a path.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Segment {
    /// A straight line.
    Line(Point, Point),
    /// A cubic Bézier curve: start, two control points, end.
    Cubic(Point, Point, Point, Point),
}

impl Segment {
    /// The point at parameter `t` in `[0, 1]`.
    pub fn at(&self, t: f64) -> Point {
        match *self {
            Segment::Line(a, b) => Point::new(a.x + (b.x - a.x) * t, a.y + (b.y - a.y) * t),
            Segment::Cubic(a, b, c, d) => {
                let u = 1.0 - t;
                let (k0, k1, k2, k3) = (u * u * u, 3.0 * u * u * t, 3.0 * u * t * t, t * t * t);
                Point::new(
                    k0 * a.x + k1 * b.x + k2 * c.x + k3 * d.x,
                    k0 * a.y + k1 * b.y + k2 * c.y + k3 * d.y,
                )
            }
        }
    }

    /// The end point.
    pub fn end(&self) -> Point {
        match *self {
            Segment::Line(_, b) | Segment::Cubic(_, _, _, b) => b,
        }
    }

    /// An upper bound of its length (the control polygon's).
    fn hull_len(&self) -> f64 {
        let d = |p: Point, q: Point| (q.x - p.x).hypot(q.y - p.y);
        match *self {
            Segment::Line(a, b) => d(a, b),
            Segment::Cubic(a, b, c, e) => d(a, b) + d(b, c) + d(c, e),
        }
    }
}

/// A path: connected segments.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Path {
    /// The segments, each starting where the previous one ends.
    pub segments: Vec<Segment>,
}

impl Path {
    /// Points along the path, no more than `step` px apart (both ends included).
    pub fn sample(&self, step: f64) -> Vec<Point> {
        let mut out = Vec::new();
        for (i, s) in self.segments.iter().enumerate() {
            let n = ((s.hull_len() / step).ceil() as usize).clamp(1, 4096);
            let first = if i == 0 { 0 } else { 1 };
            for k in first..=n {
                out.push(s.at(k as f64 / n as f64));
            }
        }
        out
    }

    /// The SVG path data (`d` attribute), one decimal per number.
    pub fn to_d(&self) -> String {
        let mut d = String::new();
        if let Some(first) = self.segments.first() {
            let start = match *first {
                Segment::Line(a, _) | Segment::Cubic(a, _, _, _) => a,
            };
            let _ = write!(d, "M{:.1},{:.1}", start.x, start.y);
        }
        for s in &self.segments {
            match *s {
                Segment::Line(_, b) => {
                    let _ = write!(d, " L{:.1},{:.1}", b.x, b.y);
                }
                Segment::Cubic(_, b, c, e) => {
                    let _ = write!(
                        d,
                        " C{:.1},{:.1} {:.1},{:.1} {:.1},{:.1}",
                        b.x, b.y, c.x, c.y, e.x, e.y
                    );
                }
            }
        }
        d
    }

    /// A path starting with a line from `a` to `b`.
    pub(crate) fn line(a: Point, b: Point) -> Path {
        Path {
            segments: vec![Segment::Line(a, b)],
        }
    }

    /// A path starting with a cubic curve.
    pub(crate) fn cubic(a: Point, b: Point, c: Point, d: Point) -> Path {
        Path {
            segments: vec![Segment::Cubic(a, b, c, d)],
        }
    }
}

/// What a label belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Owner {
    /// A line of text of box `i` of [`Scene::boxes`].
    Box(usize),
    /// The title of frame `i` of [`Scene::frames`].
    Frame(usize),
    /// The label of edge `i` of [`Scene::edges`].
    Edge(usize),
}

/// A line of text as drawn.
#[derive(Clone, Debug, PartialEq)]
pub struct Label {
    /// The text.
    pub text: String,
    /// Where the SVG `<text>` element starts: left end of the baseline.
    pub at: Point,
    /// What it covers: the estimated extent of the glyphs, and for an edge label
    /// also its white background.
    pub rect: Rect,
    /// What it belongs to.
    pub owner: Owner,
}

/// A box: an FSM behaviour, a component, a buffer or a function.
#[derive(Clone, Debug, PartialEq)]
pub struct BoxShape {
    /// Its outline.
    pub rect: Rect,
    /// The frame it is drawn in, if any.
    pub frame: Option<usize>,
}

/// A dashed frame around a group (a subsystem's FSM, an agent, a behaviour).
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// Its outline.
    pub rect: Rect,
}

/// An edge: a path with an arrow head at its end.
#[derive(Clone, Debug, PartialEq)]
pub struct Edge {
    /// The path, from the source to the arrow head.
    pub path: Path,
    /// The box it starts at (none for the start arrow of an FSM).
    pub from: Option<usize>,
    /// The box it ends at.
    pub to: Option<usize>,
    /// Its label, an index into [`Scene::labels`].
    pub label: Option<usize>,
    /// The frame it is drawn in, if any.
    pub frame: Option<usize>,
}

/// Everything an SVG drawing placed.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Scene {
    /// Width of the canvas.
    pub width: f64,
    /// Height of the canvas.
    pub height: f64,
    /// Frames, in drawing order.
    pub frames: Vec<Frame>,
    /// Boxes, in drawing order.
    pub boxes: Vec<BoxShape>,
    /// Every text label: box lines, frame titles, edge labels.
    pub labels: Vec<Label>,
    /// Edges.
    pub edges: Vec<Edge>,
}
