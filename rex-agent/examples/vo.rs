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

use rex_agent::algorithms::vo::metric::evaluate;
use rex_agent::algorithms::vo::{VoSettings, median};
use rex_bench::kitti::{Sequence, run_sequence};
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

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

fn run() -> Result<(), Box<dyn std::error::Error>> {
    let a = parse()?;
    let seq = Sequence::open(&a.seq)?;
    let n = a.frames.map_or(seq.len(), |f| f.min(seq.len()));
    let settings: VoSettings = match &a.settings {
        Some(path) => {
            let text =
                std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
            ron::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))?
        }
        None => VoSettings::default(),
    };
    let mut run = run_sequence(&seq, settings, n)?;
    let poses = &run.poses;
    let out = a.out.clone().unwrap_or_else(|| a.seq.join("vo_poses.txt"));
    let mut file = std::io::BufWriter::new(
        std::fs::File::create(&out).map_err(|e| format!("{}: {e}", out.display()))?,
    );
    for p in poses {
        let row: Vec<String> = p.iter().flatten().map(|v| format!("{v:.12e}")).collect();
        writeln!(file, "{}", row.join(" "))?;
    }
    file.flush()?;
    let stats = run.stats;
    println!(
        "frames={n} size={}x{} motions={} failures={} poses={}",
        run.size.0,
        run.size.1,
        stats.motions,
        stats.failures,
        out.display()
    );
    if let Some((k, why)) = run.failures.first() {
        eprintln!(
            "vo: {} pairs without an estimate; the first, frame {k}: {why}",
            run.failures.len()
        );
    }
    if stats.motions == 0 && n > 1 {
        return Err(format!(
            "no pair of the {n} gave a motion: there is nothing to evaluate (see the reason above)"
        )
        .into());
    }
    let (mut t_err, mut r_err) = (f64::NAN, f64::NAN);
    if let Some(gt) = &seq.poses {
        let d = evaluate(&gt[..n], poses, a.lengths.as_deref(), 10)?;
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
        median(&mut run.ms)
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
