//! Stereo visual odometry on a KITTI odometry sequence.
//!
//! ```text
//! cargo run --release -p rex-agent --example vo -- SEQ_DIR [--out POSES] [--frames N] [--lengths auto|L1,L2,...] [--settings FILE]
//! ```
//!
//! `SEQ_DIR` holds `image_0/`, `image_1/`, `calib.txt` and `times.txt` (KITTI's
//! layout; a folder with a missing or mismatched file is refused with its name).
//! The estimated poses are written in KITTI's format to `POSES` (default
//! `SEQ_DIR/vo_poses.txt`): the pose of each left camera in the frame of the first.
//! A pair without an estimate repeats the previous motion (as the peer does) and is
//! counted. With ground truth (`SEQ_DIR/poses.txt`, or KITTI's
//! `SEQ_DIR/../../poses/NN.txt`) the KITTI metric is computed; segment lengths are
//! KITTI's for paths of at least 900 m, scaled down otherwise, and printed. The last
//! line is `vo ms_per_frame=<median> t_err_pct=<..> r_err_deg_per_m=<..>`; the time
//! is the processing of a pair (PNG decoding excluded), one core. `--settings` reads
//! [`VoSettings`] from a RON file (fields left out keep their defaults).

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use rex_agent::camera::kitti::{Pose34, Sequence, compose, invert};
use rex_agent::vo::metric::evaluate;
use rex_agent::vo::{Calibration, StereoOdometry, VoSettings};

struct Args {
    seq: PathBuf,
    settings: Option<PathBuf>,
    out: Option<PathBuf>,
    frames: Option<usize>,
    lengths: Option<Vec<f64>>,
}

fn parse() -> Result<Args, String> {
    let mut it = std::env::args().skip(1);
    let mut a = Args {
        seq: PathBuf::new(),
        settings: None,
        out: None,
        frames: None,
        lengths: None,
    };
    let mut seq = None;
    while let Some(x) = it.next() {
        let mut value = || it.next().ok_or(format!("{x} needs a value"));
        match x.as_str() {
            "--out" => a.out = Some(PathBuf::from(value()?)),
            "--settings" => a.settings = Some(PathBuf::from(value()?)),
            "--frames" => a.frames = Some(value()?.parse().map_err(|e| format!("--frames: {e}"))?),
            "--lengths" => {
                let v = value()?;
                if v != "auto" {
                    let l: Result<Vec<f64>, _> = v.split(',').map(str::parse).collect();
                    a.lengths = Some(l.map_err(|e| format!("--lengths: {e}"))?);
                }
            }
            "-h" | "--help" => {
                return Err("usage: vo SEQ_DIR [--out POSES] [--frames N] [--lengths auto|L1,L2,...] [--settings FILE]".into());
            }
            other if seq.is_none() && !other.starts_with('-') => seq = Some(PathBuf::from(other)),
            other => return Err(format!("unexpected argument {other:?}")),
        }
    }
    a.seq = seq.ok_or("missing SEQ_DIR")?;
    Ok(a)
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        f64::NAN
    } else {
        v[v.len() / 2]
    }
}

fn run() -> Result<(), Box<dyn std::error::Error>> {
    let a = parse()?;
    let seq = Sequence::open(&a.seq)?;
    let n = a.frames.map_or(seq.len(), |f| f.min(seq.len()));
    let calib = Calibration {
        f: seq.focal,
        cu: seq.principal.0,
        cv: seq.principal.1,
        baseline: seq.baseline,
    };
    let settings: VoSettings = match &a.settings {
        Some(path) => {
            let text =
                std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
            ron::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))?
        }
        None => VoSettings::default(),
    };
    let mut vo = StereoOdometry::new(calib, settings)?;
    let identity: Pose34 = [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
    ];
    let mut pose = identity;
    let mut last: Option<Pose34> = None;
    let mut poses = Vec::with_capacity(n);
    let mut ms = Vec::with_capacity(n);
    let mut size = (0, 0);
    for k in 0..n {
        let (w, h, left, right) = seq.frame(k)?;
        size = (w, h);
        let t = Instant::now();
        let r = vo.process(&left, &right, w as usize, h as usize);
        ms.push(t.elapsed().as_secs_f64() * 1e3);
        let motion = match r {
            Ok(Some(m)) => {
                let tr: Pose34 = [m.tr[0], m.tr[1], m.tr[2]];
                last = Some(tr);
                Some(tr)
            }
            Ok(None) => None,
            // No estimate: the previous motion again (constant velocity).
            Err(_) => last,
        };
        if let Some(tr) = motion {
            pose = compose(&pose, &invert(&tr));
        }
        poses.push(pose);
    }
    let out = a.out.clone().unwrap_or_else(|| a.seq.join("vo_poses.txt"));
    let mut file = std::io::BufWriter::new(
        std::fs::File::create(&out).map_err(|e| format!("{}: {e}", out.display()))?,
    );
    for p in &poses {
        let row: Vec<String> = p.iter().flatten().map(|v| format!("{v:.12e}")).collect();
        writeln!(file, "{}", row.join(" "))?;
    }
    file.flush()?;
    let stats = vo.stats();
    println!(
        "frames={n} size={}x{} motions={} failures={} poses={}",
        size.0,
        size.1,
        stats.motions,
        stats.failures,
        out.display()
    );
    let (mut t_err, mut r_err) = (f64::NAN, f64::NAN);
    if let Some(gt) = &seq.poses {
        let d = evaluate(&gt[..n], &poses, a.lengths.as_deref(), 10)?;
        let lengths: Vec<String> = d.lengths.iter().map(|l| format!("{l}")).collect();
        println!(
            "kitti metric over lengths {} m ({} segments), ground-truth path {:.1} m",
            lengths.join(","),
            d.segments,
            d.path_length
        );
        t_err = d.t_err_pct;
        r_err = d.r_err_deg_per_m;
    }
    println!(
        "vo ms_per_frame={:.1} t_err_pct={t_err:.3} r_err_deg_per_m={r_err:.5}",
        median(&mut ms)
    );
    Ok(())
}

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("vo: {e}");
            ExitCode::FAILURE
        }
    }
}
