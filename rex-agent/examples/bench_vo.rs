//! Stereo visual odometry on sequences written by the simulator, beside the OpenCV
//! peer on the same sequences in the same run.
//!
//! ```text
//! cargo run --release -p rex-agent --example bench_vo [-- --peer PEERS_DIR] [--dir DIR] [--no-peer] [--quick]
//! ```
//!
//! Four sequences are rendered once into `DIR` (default `target/vo-bench`), and
//! again when the stored first or last pair is not what the renderer makes now:
//!
//! | sequence | size | path | camera | role |
//! |---|---|---|---|---|
//! | `sim_640x480` | 640 × 480, f 400 | figure eight, 20 s (200 pairs) | ideal | tuned on |
//! | `sim_1241x376` | 1241 × 376, f 718.856 (KITTI's) | figure eight, 10 s | ideal | tuned on |
//! | `tour11_640x480` | 640 × 480 | tour seed 11, 200 m | noisy, seed 11 | held out |
//! | `tour12_1241x376` | 1241 × 376 | tour seed 12, 200 m | noisy, seed 12 | held out |
//!
//! `VoSettings::default()` was tuned on the first two and on two noisy tuning
//! tours of other seeds (21, 22: `kitti_sequence --path tour:21 --sensor
//! realistic:21`); the tours here (another path, a noisy sensor:
//! `SensorConfig::realistic`, with motion blur) were not used to choose any
//! setting. Our odometry runs on one thread; the peer
//! (`PEERS_DIR/opencv_stereo_vo.py`, default `../shared/peers`) on one OpenCV
//! thread, in a Python environment the bench makes once in `target/peer-venv`
//! (`pip install opencv-python-headless numpy`). Both are timed per pair over the
//! whole sequence (image decoding excluded), one pass each; both are scored with
//! the same KITTI metric (ours, on the peer's written poses), segment lengths
//! chosen from the path (printed). Per sequence the bench prints `ms_per_frame`
//! median, mean, p99 and max for both, and the drift. The last line is
//! `vo_ms_ratio=<ours/peer, of the mean time per pair, mean over the sequences>
//! t_err_ratio=<ours/peer, mean over the held-out sequences>`; the line before it
//! keeps the old figure, `vo ms_per_frame=.. t_err_pct=.. r_err_deg_per_m=..`
//! for `sim_640x480`. `--quick` renders 300 pairs of each tour instead of 200 m.

use std::path::{Path, PathBuf};
use std::process::Command;

use rex_agent::algorithms::vo::VoSettings;
use rex_agent::algorithms::vo::metric::evaluate;
use rex_agent::world::WorldConfig;
use rex_agent::world::camera::{Renderer, SensorConfig};
use rex_bench::kitti::{
    ScriptedPath, Sequence, is_current, read_poses, run_sequence, write_scripted,
};

type Error = Box<dyn std::error::Error>;

#[path = "common/peer_python.rs"]
mod common;

/// One side's figures on one sequence.
struct Figures {
    ms: Timing,
    t_err: f64,
    r_err: f64,
    lengths: String,
    path_m: f64,
}

/// Time per pair \[ms\].
#[derive(Clone, Copy)]
struct Timing {
    median: f64,
    mean: f64,
    p99: f64,
    max: f64,
}

impl Timing {
    fn of(ms: &[f64]) -> Timing {
        let mut v = ms.to_vec();
        v.sort_by(f64::total_cmp);
        let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
        Timing {
            median: at(0.5),
            mean: v.iter().sum::<f64>() / v.len() as f64,
            p99: at(0.99),
            max: v[v.len() - 1],
        }
    }
}

impl std::fmt::Display for Timing {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "median {:.1} mean {:.1} p99 {:.1} max {:.1} ms/pair",
            self.median, self.mean, self.p99, self.max
        )
    }
}

struct Case {
    name: &'static str,
    width: u32,
    height: u32,
    focal: f64,
    path: ScriptedPath,
    /// Pairs, or metres of path.
    extent: Extent,
    sensor: SensorConfig,
    held_out: bool,
}

enum Extent {
    Pairs(usize),
    Metres(f64),
}

fn sequence(dir: &Path, case: &Case, quick: bool) -> Result<Sequence, Error> {
    let frames = match case.extent {
        Extent::Pairs(n) => n,
        Extent::Metres(_) if quick => 300,
        Extent::Metres(m) => case.path.frames_for(m),
    };
    let mut world = WorldConfig::shipped()?;
    world.camera.width = case.width;
    world.camera.height = case.height;
    world.camera.focal = case.focal;
    world.camera.sensor = case.sensor.clone();
    let mut renderer = Renderer::new(world.camera, world.scene)?;
    // Rendered before, by this renderer with this camera and scene: reused.
    if let Ok(seq) = Sequence::open(dir) {
        match is_current(&seq, &mut renderer, case.path, frames) {
            Ok(true) => return Ok(seq),
            Ok(false) => eprintln!(
                "{} is not what the renderer makes now (another version, camera or length): rendering it again",
                dir.display()
            ),
            Err(e) => eprintln!("{e}: rendering {} again", dir.display()),
        }
    }
    eprintln!(
        "rendering {frames} pairs of {}x{} into {}",
        case.width,
        case.height,
        dir.display()
    );
    write_scripted(dir, &mut renderer, case.path, frames)?;
    Ok(Sequence::open(dir)?)
}

fn score(seq: &Sequence, poses: &[[[f64; 4]; 3]], ms: &[f64]) -> Result<Figures, Error> {
    let gt = seq
        .poses
        .as_ref()
        .ok_or("the sequence has no ground truth")?;
    if poses.len() != gt.len() || ms.is_empty() {
        return Err(format!("{} poses for {} frames", poses.len(), gt.len()).into());
    }
    let d = evaluate(gt, poses, None, 10)?;
    Ok(Figures {
        ms: Timing::of(ms),
        t_err: d.t_err_pct,
        r_err: d.r_err_deg_per_m,
        lengths: d
            .lengths
            .iter()
            .map(|l| format!("{l}"))
            .collect::<Vec<_>>()
            .join(","),
        path_m: d.path_length,
    })
}

fn ours(seq: &Sequence) -> Result<(Figures, usize), Error> {
    let run = run_sequence(seq, VoSettings::default(), seq.len())?;
    Ok((score(seq, &run.poses, &run.ms)?, run.failures.len()))
}

/// The Python with OpenCV, made in `target/peer-venv` the first time.
fn peer_python() -> Result<PathBuf, Error> {
    Ok(common::peer_python(
        "import cv2, numpy",
        &["opencv-python-headless>=4.8,<5", "numpy"],
    )?)
}

/// The peer on `dir`, one OpenCV thread, each `process` call timed.
fn peer(python: &Path, peers: &Path, seq: &Sequence, dir: &Path) -> Result<Figures, Error> {
    let out = std::env::temp_dir().join(format!("bench_vo_peer_{}.txt", std::process::id()));
    let times = out.with_extension("ms");
    let script = format!(
        r#"
import sys, time, cv2
cv2.setNumThreads(1)
sys.path.insert(0, {peers:?})
import opencv_stereo_vo as p
ms = []
process = p.StereoVO.process
def timed(self, L, R):
    t = time.perf_counter()
    r = process(self, L, R)
    ms.append(1e3 * (time.perf_counter() - t))
    return r
p.StereoVO.process = timed
p.main(sys.argv[1:])
open({times:?}, "w").write("\n".join("%.6f" % m for m in ms))
"#,
        peers = peers.display().to_string(),
        times = times.display().to_string(),
    );
    let output = Command::new(python)
        .arg("-c")
        .arg(script)
        .arg(dir)
        .arg("--out")
        .arg(&out)
        .output()?;
    if !output.status.success() {
        return Err(format!("peer: {}", String::from_utf8_lossy(&output.stderr).trim()).into());
    }
    let poses = read_poses(&out)?;
    let ms: Vec<f64> = std::fs::read_to_string(&times)?
        .lines()
        .map(str::parse)
        .collect::<Result<_, _>>()?;
    let _ = std::fs::remove_file(&out);
    let _ = std::fs::remove_file(&times);
    score(seq, &poses, &ms)
}

/// The four sequences: two tuned on, two held out (KITTI's size among them).
fn cases() -> [Case; 4] {
    let kitti = (1241, 376, 718.856);
    [
        Case {
            name: "sim_640x480",
            width: 640,
            height: 480,
            focal: 400.0,
            path: ScriptedPath::FigureEight,
            extent: Extent::Pairs(200),
            sensor: SensorConfig::default(),
            held_out: false,
        },
        Case {
            name: "sim_1241x376",
            width: kitti.0,
            height: kitti.1,
            focal: kitti.2,
            path: ScriptedPath::FigureEight,
            extent: Extent::Pairs(100),
            sensor: SensorConfig::default(),
            held_out: false,
        },
        Case {
            name: "tour11_640x480",
            width: 640,
            height: 480,
            focal: 400.0,
            path: ScriptedPath::Tour(11),
            extent: Extent::Metres(200.0),
            sensor: SensorConfig::realistic(11),
            held_out: true,
        },
        Case {
            name: "tour12_1241x376",
            width: kitti.0,
            height: kitti.1,
            focal: kitti.2,
            path: ScriptedPath::Tour(12),
            extent: Extent::Metres(200.0),
            sensor: SensorConfig::realistic(12),
            held_out: true,
        },
    ]
}

/// The ratios ours / peer over the sequences, as the figure lines report them.
#[derive(Default)]
struct Ratios {
    /// Mean time per frame, every sequence the peer ran.
    time: Vec<f64>,
    /// Translation drift, the held-out sequences.
    drift: Vec<f64>,
}

/// Run the peer on `seq` (at `path`) and print its figures beside ours, `o`.
fn compare(
    python: &Path,
    peers: &Path,
    seq: &Sequence,
    path: &Path,
    case: &Case,
    o: &Figures,
    ratios: &mut Ratios,
) {
    match peer(python, peers, seq, path) {
        Ok(p) => {
            println!(
                "#   peer (OpenCV, one thread): {}, t_err {:.3} %, r_err {:.5} deg/m",
                p.ms, p.t_err, p.r_err
            );
            println!(
                "#   ours / peer: time (mean) {:.3}, time (median) {:.3}, t_err {:.3}, r_err {:.3}",
                o.ms.mean / p.ms.mean,
                o.ms.median / p.ms.median,
                o.t_err / p.t_err,
                o.r_err / p.r_err
            );
            ratios.time.push(o.ms.mean / p.ms.mean);
            if case.held_out {
                ratios.drift.push(o.t_err / p.t_err);
            }
        }
        Err(e) => println!("#   peer: no figures ({e})"),
    }
}

fn main() -> Result<(), Error> {
    let args: Vec<String> = std::env::args().collect();
    let arg = |name: &str| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
    };
    let flag = |name: &str| args.iter().any(|a| a == name);
    let dir = arg("--dir").map_or_else(|| PathBuf::from("target/vo-bench"), PathBuf::from);
    let peers = arg("--peer").map_or_else(|| PathBuf::from("../shared/peers"), PathBuf::from);
    let quick = flag("--quick");
    let with_peer = !flag("--no-peer");
    let python = if with_peer {
        match peer_python() {
            Ok(p) => Some(p),
            Err(e) => {
                eprintln!("the peer cannot run: {e}");
                None
            }
        }
    } else {
        None
    };
    let mut ratios = Ratios::default();
    let mut old = None;
    for case in &cases() {
        let path = dir.join(if quick && case.held_out {
            format!("{}_quick", case.name)
        } else {
            case.name.to_owned()
        });
        let seq = sequence(&path, case, quick)?;
        let (o, failures) = ours(&seq)?;
        let role = if case.held_out {
            "held out"
        } else {
            "tuned on"
        };
        println!(
            "# {} ({role}; {} pairs, {:.0} m, lengths {} m)",
            case.name,
            seq.len(),
            o.path_m,
            o.lengths
        );
        println!(
            "#   ours: {}, t_err {:.3} %, r_err {:.5} deg/m, {failures} pairs without an estimate",
            o.ms, o.t_err, o.r_err
        );
        if let Some(python) = &python {
            compare(python, &peers, &seq, &path, case, &o, &mut ratios);
        }
        if case.name == "sim_640x480" {
            old = Some(o);
        }
    }
    if let Some(o) = old {
        println!(
            "vo ms_per_frame={:.1} t_err_pct={:.3} r_err_deg_per_m={:.5}",
            o.ms.median, o.t_err, o.r_err
        );
    }
    let mean = |v: &[f64]| {
        if v.is_empty() {
            f64::NAN
        } else {
            v.iter().sum::<f64>() / v.len() as f64
        }
    };
    println!(
        "vo_ms_ratio={:.3} t_err_ratio={:.3}",
        mean(&ratios.time),
        mean(&ratios.drift)
    );
    Ok(())
}
