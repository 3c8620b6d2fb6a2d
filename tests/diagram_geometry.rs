//! The geometry of the SVG diagrams: no text label overlaps another label or a box
//! it does not belong to, no edge passes through a box, every edge label touches its
//! edge, titles fit in their frames, for every spec in the repo (every diagram kind,
//! for every selection the CLI offers) and for random FSMs and systems.
//!
//! The geometry is what the renderer placed, recorded as it writes the SVG
//! ([`render_svg_scene`]); [`assert_scene_is_the_svg`] checks that the recording is
//! what the SVG draws (every `<text>`, `<path>`, box and frame, at the same
//! coordinates), so the rules below judge the picture a user sees. Text extents are
//! estimated like the renderer does: 7.3 px per character of the 12 px monospace font,
//! 9.6 px above the baseline and 3 px below.
//!
//! Rules and tolerances (px): labels may overlap by less than 0.5 (rounding); a label
//! keeps 2 clear of a frame's border (inside or outside it); paths are sampled every
//! 2 or less, and a sample may not lie more than 0.5 inside a box, a foreign frame or
//! another edge's label; an edge label must come within 4 of its edge, and no other
//! edge may come nearer to it than its own.
//!
//! A fixed sample of 100 random FSMs and 100 random systems runs on every `cargo
//! test` (its counts are logged with `--nocapture`), and the random properties 64
//! more cases each; for a longer pass:
//!
//! ```text
//! PROPTEST_CASES=2000 cargo test -p embodied --test diagram_geometry
//! ```

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};

use embodied::spec::check_file;
use embodied::spec::diagram::geometry::{Owner, Point, Rect, Scene};
use embodied::spec::diagram::{Kind, render_svg_scene};
use embodied::spec::model::Spec;
use proptest::prelude::*;
use proptest::strategy::ValueTree;
use proptest::test_runner::{Config, TestRunner};

#[path = "diagram_geometry/random.rs"]
mod random;
use random::*;

/// Overlaps thinner than this are rounding (numbers are written with one decimal).
const TOL: f64 = 0.5;
/// A label touches its edge when some point of the edge is this close to it.
const TOUCH: f64 = 4.0;
/// Labels keep out of this band on either side of a frame's border.
const BORDER: f64 = 2.0;
/// Paths are sampled at most this far apart.
const STEP: f64 = 2.0;

/// The rules, in the order they are reported.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Rule {
    /// (a) Two labels overlap.
    LabelOverLabel,
    /// (b) A label overlaps a box it does not belong to, or leaves its own box.
    LabelOverBox,
    /// (b) A label lies on a frame's border, or in a frame it does not belong to,
    /// or outside the frame it belongs to.
    LabelOverFrame,
    /// (c) An edge passes through a box (its own ends' included: it may touch them).
    EdgeThroughBox,
    /// (c) An edge passes through a frame that holds neither of its ends, or leaves
    /// the frame that holds both.
    EdgeThroughFrame,
    /// (c') An edge passes through a label other than its own.
    EdgeThroughLabel,
    /// (d) An edge label does not touch its edge.
    LabelOffEdge,
    /// (d') Another edge comes nearer to an edge label than its own.
    LabelNearerOtherEdge,
    /// (e) A frame's title does not fit in the frame.
    TitleOutsideFrame,
    /// Something lies outside the canvas.
    OutsideCanvas,
}

#[derive(Clone, Debug)]
struct Violation {
    rule: Rule,
    what: String,
}

impl fmt::Display for Violation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:?}: {}", self.rule, self.what)
    }
}

fn show(r: &Rect) -> String {
    format!("[{:.1},{:.1} {:.1}x{:.1}]", r.x, r.y, r.w, r.h)
}

/// Every rule broken by the scene.
fn violations(s: &Scene) -> Vec<Violation> {
    let mut c = Checker::new(s);
    c.labels_over_labels();
    for i in 0..s.labels.len() {
        c.label_in_canvas(i);
        c.label_and_boxes(i);
        c.label_and_frames(i);
    }
    for e in 0..s.edges.len() {
        c.edge_through_boxes(e);
        c.edge_through_frames(e);
        c.edge_in_canvas(e);
        c.edge_through_labels(e);
        c.label_on_edge(e);
    }
    c.out
}

/// The rules judged on one scene: the violations found so far.
struct Checker<'s> {
    s: &'s Scene,
    /// The canvas, with the tolerance.
    canvas: Rect,
    /// Each edge's path, sampled every [`STEP`].
    samples: Vec<Vec<Point>>,
    out: Vec<Violation>,
}

impl<'s> Checker<'s> {
    fn new(s: &'s Scene) -> Self {
        Checker {
            s,
            canvas: Rect::new(0.0, 0.0, s.width, s.height).inflate(TOL),
            samples: s.edges.iter().map(|e| e.path.sample(STEP)).collect(),
            out: Vec::new(),
        }
    }

    fn v(&mut self, rule: Rule, what: String) {
        self.out.push(Violation { rule, what });
    }

    fn label(&self, i: usize) -> String {
        let s = self.s;
        format!("label {:?} {}", s.labels[i].text, show(&s.labels[i].rect))
    }

    fn edge_name(&self, e: usize) -> String {
        let s = self.s;
        let ed = &s.edges[e];
        match ed.label {
            Some(l) => format!("edge {e} ({:?})", s.labels[l].text),
            None => format!("edge {e} (box {:?} -> box {:?})", ed.from, ed.to),
        }
    }

    /// The frames of an edge's ends.
    fn end_frames(&self, e: usize) -> Vec<usize> {
        let s = self.s;
        let ed = &s.edges[e];
        let mut fs: Vec<usize> = [ed.from, ed.to]
            .into_iter()
            .flatten()
            .filter_map(|b| s.boxes[b].frame)
            .collect();
        fs.dedup();
        fs
    }

    /// Whether all the (drawn) ends of edge `e` are in frame `f`.
    fn inside_frame(&self, e: usize, f: usize) -> bool {
        let s = self.s;
        let ed = &s.edges[e];
        [ed.from, ed.to]
            .into_iter()
            .flatten()
            .all(|b| s.boxes[b].frame == Some(f))
    }

    /// (a) labels over labels
    fn labels_over_labels(&mut self) {
        let s = self.s;
        for i in 0..s.labels.len() {
            for j in i + 1..s.labels.len() {
                if s.labels[i].rect.inflate(-TOL).overlaps(&s.labels[j].rect) {
                    let what = format!("{} overlaps {}", self.label(i), self.label(j));
                    self.v(Rule::LabelOverLabel, what);
                }
            }
        }
    }

    fn label_in_canvas(&mut self, i: usize) {
        if !self.canvas.contains(&self.s.labels[i].rect) {
            let what = self.label(i);
            self.v(Rule::OutsideCanvas, what);
        }
    }

    /// (b) labels over boxes
    fn label_and_boxes(&mut self, i: usize) {
        let s = self.s;
        let l = &s.labels[i];
        let r = l.rect.inflate(-TOL);
        for (b, bx) in s.boxes.iter().enumerate() {
            if l.owner == Owner::Box(b) {
                if !bx.rect.contains(&r) {
                    let what = format!("{} leaves its box {}", self.label(i), show(&bx.rect));
                    self.v(Rule::LabelOverBox, what);
                }
            } else if r.overlaps(&bx.rect) {
                let what = format!("{} overlaps box {b} {}", self.label(i), show(&bx.rect));
                self.v(Rule::LabelOverBox, what);
            }
        }
    }

    /// (b, e) labels and frames
    fn label_and_frames(&mut self, i: usize) {
        let s = self.s;
        let l = &s.labels[i];
        for (f, fr) in s.frames.iter().enumerate() {
            let inner = fr.rect.inflate(-BORDER);
            let inside = inner.contains(&l.rect);
            let outside = !fr.rect.inflate(BORDER).overlaps(&l.rect);
            // Must the label be inside (Some(true)), outside (Some(false)), either?
            let belongs = match l.owner {
                Owner::Frame(g) => Some(g == f),
                Owner::Box(b) => Some(s.boxes[b].frame == Some(f)),
                Owner::Edge(e) if self.inside_frame(e, f) => Some(true),
                Owner::Edge(e) if self.end_frames(e).contains(&f) => None,
                Owner::Edge(_) => Some(false),
            };
            let ok = match belongs {
                Some(true) => inside,
                Some(false) => outside,
                None => inside || outside,
            };
            if !ok {
                let rule = if l.owner == Owner::Frame(f) {
                    Rule::TitleOutsideFrame
                } else {
                    Rule::LabelOverFrame
                };
                let how = match belongs {
                    Some(true) => "is not inside",
                    Some(false) => "is not outside",
                    None => "lies on the border of",
                };
                let what = format!("{} {how} frame {f} {}", self.label(i), show(&fr.rect));
                self.v(rule, what);
            }
        }
    }

    /// (c) edges through boxes
    fn edge_through_boxes(&mut self, e: usize) {
        let s = self.s;
        for (b, bx) in s.boxes.iter().enumerate() {
            let inner = bx.rect.inflate(-TOL);
            if let Some(p) = self.samples[e].iter().find(|p| inner.has_inside(**p)) {
                let what = format!(
                    "{} passes through box {b} {} at ({:.1},{:.1})",
                    self.edge_name(e),
                    show(&bx.rect),
                    p.x,
                    p.y
                );
                self.v(Rule::EdgeThroughBox, what);
            }
        }
    }

    /// (c) edges through frames that hold neither end, or out of the frame
    /// that holds both
    fn edge_through_frames(&mut self, e: usize) {
        let s = self.s;
        let ends = self.end_frames(e);
        for (f, fr) in s.frames.iter().enumerate() {
            let pts = &self.samples[e];
            let bad = if !ends.contains(&f) {
                let inner = fr.rect.inflate(-TOL);
                pts.iter().find(|p| inner.has_inside(**p))
            } else if self.inside_frame(e, f) {
                let outer = fr.rect.inflate(TOL);
                pts.iter().find(|p| outer.distance(**p) > 0.0)
            } else {
                None
            };
            if let Some(p) = bad {
                let what = format!(
                    "{} crosses frame {f} {} at ({:.1},{:.1})",
                    self.edge_name(e),
                    show(&fr.rect),
                    p.x,
                    p.y
                );
                self.v(Rule::EdgeThroughFrame, what);
            }
        }
    }

    fn edge_in_canvas(&mut self, e: usize) {
        let canvas = self.canvas;
        if let Some(p) = self.samples[e].iter().find(|p| canvas.distance(**p) > 0.0) {
            let what = format!("{} at ({:.1},{:.1})", self.edge_name(e), p.x, p.y);
            self.v(Rule::OutsideCanvas, what);
        }
    }

    /// (c') edges through other labels (box lines are covered by (c))
    fn edge_through_labels(&mut self, e: usize) {
        let s = self.s;
        for (i, l) in s.labels.iter().enumerate() {
            if matches!(l.owner, Owner::Box(_)) || l.owner == Owner::Edge(e) {
                continue;
            }
            let inner = l.rect.inflate(-TOL);
            if self.samples[e].iter().any(|p| inner.has_inside(*p)) {
                let what = format!("{} passes through {}", self.edge_name(e), self.label(i));
                self.v(Rule::EdgeThroughLabel, what);
            }
        }
    }

    /// (d) the label on its edge, and no other edge nearer to it
    fn label_on_edge(&mut self, e: usize) {
        let s = self.s;
        let Some(i) = s.edges[e].label else {
            return;
        };
        let r = &s.labels[i].rect;
        let dist = |e: usize| {
            self.samples[e]
                .iter()
                .map(|p| r.distance(*p))
                .fold(f64::INFINITY, f64::min)
        };
        let own = dist(e);
        let mut found = Vec::new();
        if own > TOUCH {
            found.push((
                Rule::LabelOffEdge,
                format!("{} is {own:.1} px from its edge", self.label(i)),
            ));
        }
        for o in (0..s.edges.len()).filter(|&o| o != e) {
            let d = dist(o);
            if d + TOL < own {
                found.push((
                    Rule::LabelNearerOtherEdge,
                    format!(
                        "{} is {d:.1} px from {}, {own:.1} px from its own",
                        self.label(i),
                        self.edge_name(o)
                    ),
                ));
            }
        }
        for (rule, what) in found {
            self.v(rule, what);
        }
    }
}

/// The recorded scene is what the SVG draws: the same texts at the same places, the
/// same paths, boxes and frames.
fn assert_scene_is_the_svg(svg: &str, s: &Scene) {
    fn attr<'a>(line: &'a str, name: &str) -> Option<&'a str> {
        let key = format!(" {name}=\"");
        let start = line.find(&key)? + key.len();
        let len = line[start..].find('"')?;
        Some(&line[start..start + len])
    }
    fn unesc(s: &str) -> String {
        s.replace("&lt;", "<")
            .replace("&gt;", ">")
            .replace("&quot;", "\"")
            .replace("&#39;", "'")
            .replace("&amp;", "&")
    }
    let f = |x: f64| format!("{x:.1}");
    let rect = |r: &Rect| format!("{} {} {} {}", f(r.x), f(r.y), f(r.w), f(r.h));
    let (mut texts, mut paths, mut boxes, mut frames) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for line in svg.lines() {
        if line.starts_with("<text ") {
            let body = &line[line.find('>').unwrap() + 1..line.rfind("</text>").unwrap()];
            texts.push(format!(
                "{} {} {}",
                attr(line, "x").unwrap(),
                attr(line, "y").unwrap(),
                unesc(body)
            ));
        } else if line.starts_with("<path ") && attr(line, "fill") == Some("none") {
            paths.push(attr(line, "d").unwrap().to_owned());
        } else if line.starts_with("<rect ") && attr(line, "stroke").is_some() {
            let r = ["x", "y", "width", "height"].map(|a| attr(line, a).unwrap());
            let r = r.join(" ");
            if attr(line, "stroke-dasharray").is_some() {
                frames.push(r);
            } else if attr(line, "fill") != Some("none") {
                boxes.push(r);
            }
        }
    }
    let mut want_texts: Vec<String> = s
        .labels
        .iter()
        .map(|l| format!("{} {} {}", f(l.at.x), f(l.at.y), l.text))
        .collect();
    let mut want_paths: Vec<String> = s.edges.iter().map(|e| e.path.to_d()).collect();
    let want_boxes: Vec<String> = s.boxes.iter().map(|b| rect(&b.rect)).collect();
    let want_frames: Vec<String> = s.frames.iter().map(|b| rect(&b.rect)).collect();
    for v in [&mut texts, &mut paths, &mut want_texts, &mut want_paths] {
        v.sort();
    }
    assert_eq!(texts, want_texts, "the labels recorded are the SVG's");
    assert_eq!(paths, want_paths, "the paths recorded are the SVG's");
    assert_eq!(boxes, want_boxes, "the boxes recorded are the SVG's");
    assert_eq!(frames, want_frames, "the frames recorded are the SVG's");
    assert!(
        svg.starts_with(&format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{}" height="{}""#,
            f(s.width),
            f(s.height)
        )),
        "the canvas recorded is the SVG's"
    );
}

/// Every diagram the CLI can draw of `spec` as SVG: each kind, for the whole spec
/// and for each `--subsystem`.
fn diagrams(spec: &Spec) -> Vec<(Kind, Option<String>)> {
    let mut selections = vec![None];
    selections.extend(
        spec.agents
            .iter()
            .flat_map(|a| &a.subsystems)
            .map(|s| Some(s.name.clone())),
    );
    [Kind::Fsm, Kind::Structure, Kind::Dataflow]
        .into_iter()
        .flat_map(|k| selections.iter().map(move |s| (k, s.clone())))
        .collect()
}

/// The violations of every diagram of `spec`, by kind, each described with the
/// diagram it is in.
fn check_spec(spec: &Spec, name: &str) -> BTreeMap<String, Vec<String>> {
    let mut out: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for (kind, sub) in diagrams(spec) {
        let (svg, scene) = render_svg_scene(spec, kind, sub.as_deref()).unwrap();
        assert_scene_is_the_svg(&svg, &scene);
        let found = violations(&scene);
        let entry = out.entry(kind.to_string()).or_default();
        entry.extend(
            found
                .into_iter()
                .map(|v| format!("{name} {kind} {}: {v}", sub.as_deref().unwrap_or("(all)"))),
        );
    }
    out
}

fn repo_specs() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    for dir in ["specs", "tests/specs/valid"] {
        for entry in std::fs::read_dir(root.join(dir)).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "ron") {
                files.push(path);
            }
        }
    }
    files.sort();
    files
}

/// A count of violations per kind and rule, for the log.
fn summary(found: &BTreeMap<String, Vec<String>>) -> String {
    let mut out = String::new();
    for (kind, list) in found {
        let mut per_rule: BTreeMap<&str, usize> = BTreeMap::new();
        for v in list {
            let rule = v.split(": ").nth(1).unwrap_or("?");
            *per_rule.entry(rule).or_default() += 1;
        }
        out.push_str(&format!("{kind}: {} {per_rule:?}\n", list.len()));
    }
    out
}

#[test]
fn the_repo_specs_draw_cleanly() {
    let files = repo_specs();
    assert!(files.len() >= 4, "{files:?}");
    let mut all: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for path in &files {
        let (spec, report) = check_file(path).unwrap();
        let spec = spec.unwrap_or_else(|| panic!("{}: {}", path.display(), report.render(100)));
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        for (kind, list) in check_spec(&spec, &name) {
            all.entry(kind).or_default().extend(list);
        }
    }
    eprintln!("repo specs, violations per kind:\n{}", summary(&all));
    let list: Vec<&String> = all.values().flatten().collect();
    assert!(
        list.is_empty(),
        "{} violations:\n{}",
        list.len(),
        list.iter()
            .take(40)
            .map(|s| s.as_str())
            .collect::<Vec<_>>()
            .join("\n")
    );
}

fn config(default: u32) -> Config {
    let cases = std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(default);
    Config {
        cases,
        failure_persistence: None,
        ..Config::default()
    }
}

/// The first violation of any diagram of `spec`, as a test failure.
fn clean(spec: &Spec) -> Result<(), TestCaseError> {
    let found = check_spec(spec, &spec.name);
    let list: Vec<&String> = found.values().flatten().collect();
    if list.is_empty() {
        Ok(())
    } else {
        let ron = embodied::spec::options()
            .to_string_pretty(spec, ron::ser::PrettyConfig::default())
            .unwrap_or_default();
        Err(TestCaseError::fail(format!(
            "{} violations, first: {}\n{}",
            list.len(),
            list[0],
            ron
        )))
    }
}

proptest! {
    #![proptest_config(config(64))]

    #[test]
    fn random_fsms_draw_cleanly(spec in random_fsms()) {
        clean(&spec)?;
    }

    #[test]
    fn random_systems_draw_cleanly(plan in system_plan()) {
        clean(&build_system(&plan))?;
    }
}

/// How many of `cases` random specs (a fixed seed) break a rule, per diagram kind,
/// and the violations per rule: the numbers to compare between layouts.
fn census<S: Strategy>(
    strategy: S,
    build: impl Fn(&S::Value) -> Spec,
    cases: usize,
) -> (String, usize) {
    let mut runner = TestRunner::deterministic();
    let mut specs_with: BTreeMap<String, usize> = BTreeMap::new();
    let mut total: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for _ in 0..cases {
        let value = strategy.new_tree(&mut runner).unwrap().current();
        let spec = build(&value);
        for (kind, list) in check_spec(&spec, "random") {
            if !list.is_empty() {
                *specs_with.entry(kind.clone()).or_default() += 1;
            }
            total.entry(kind).or_default().extend(list);
        }
    }
    let n = total.values().map(Vec::len).sum();
    (
        format!(
            "specs with a violation per kind (of {cases}): {specs_with:?}\n{}",
            summary(&total)
        ),
        n,
    )
}

/// The same 100 random FSMs and 100 random systems on every run: a fixed sample
/// whose counts the log shows (`--nocapture`), and which must stay clean.
#[test]
fn a_fixed_sample_of_random_specs_draws_cleanly() {
    let (fsms, a) = census(random_fsms(), Clone::clone, 100);
    let (systems, b) = census(system_plan(), build_system, 100);
    eprintln!("random FSMs: {fsms}\nrandom systems: {systems}");
    assert_eq!(a + b, 0, "random FSMs: {fsms}\nrandom systems: {systems}");
}
