//! Stereo visual odometry on sequences written by the simulator, beside the OpenCV
//! peer on the same sequences.
//!
//! ```text
//! cargo run --release -p rex-agent --example bench_vo [-- --peer PEERS_DIR] [--dir DIR]
//! ```
//!
//! Two sequences are rendered once into `DIR` (default `target/vo-bench`), along the
//! figure eight of the missions at 10 pairs per second: 200 pairs at 640 × 480 (the
//! camera of the world) and 100 at KITTI's size, 1241 × 376 with KITTI's focal
//! length 718.856. Our odometry runs single-threaded; the time is the processing of
//! a pair (PNG decoding excluded), median over the sequence. With `--peer`,
//! `PEERS_DIR/opencv_stereo_vo.py` runs on the same files, once with OpenCV's
//! default threads and once on one thread. The drift uses the KITTI metric with
//! segment lengths scaled to the short paths (printed). The last line is
//! `vo ms_per_frame=<..> t_err_pct=<..> r_err_deg_per_m=<..>` for 640 × 480.

use std::path::{Path, PathBuf};

use rex_agent::algorithms::vo::metric::evaluate;
use rex_agent::algorithms::vo::{VoSettings, median};
use rex_agent::world::WorldConfig;
use rex_agent::world::camera::Renderer;
use rex_agent::world::camera::kitti::{ScriptedPath, Sequence, run_sequence, write_scripted};

struct Figures {
    ms: f64,
    t_err: f64,
    r_err: f64,
    lengths: String,
}

fn sequence(
    dir: &Path,
    width: u32,
    height: u32,
    focal: f64,
    frames: usize,
) -> Result<Sequence, Box<dyn std::error::Error>> {
    if let Ok(seq) = Sequence::open(dir)
        && seq.len() == frames
    {
        return Ok(seq);
    }
    let mut world = WorldConfig::shipped()?;
    world.camera.width = width;
    world.camera.height = height;
    world.camera.focal = focal;
    let renderer = Renderer::new(world.camera, world.scene)?;
    eprintln!(
        "rendering {frames} pairs of {width}x{height} into {}",
        dir.display()
    );
    write_scripted(dir, &renderer, ScriptedPath::FigureEight, frames)?;
    Ok(Sequence::open(dir)?)
}

fn ours(seq: &Sequence) -> Result<Figures, Box<dyn std::error::Error>> {
    let mut run = run_sequence(seq, VoSettings::default(), seq.len())?;
    let gt = seq
        .poses
        .as_ref()
        .ok_or("the sequence has no ground truth")?;
    let d = evaluate(gt, &run.poses, None, 10)?;
    Ok(Figures {
        ms: median(&mut run.ms),
        t_err: d.t_err_pct,
        r_err: d.r_err_deg_per_m,
        lengths: d
            .lengths
            .iter()
            .map(|l| format!("{l}"))
            .collect::<Vec<_>>()
            .join(","),
    })
}

fn peer(peers: &str, seq: &Path, threads: Option<u32>) -> Option<Figures> {
    let script = Path::new(peers).join("opencv_stereo_vo.py");
    let out = std::env::temp_dir().join("bench_vo_peer_poses.txt");
    let gt = seq.join("poses.txt");
    let mut cmd = std::process::Command::new("python3");
    match threads {
        // The peer has no thread option: set OpenCV's before its main runs.
        Some(n) => {
            cmd.arg("-c").arg(format!(
                "import sys, cv2; cv2.setNumThreads({n}); sys.path.insert(0, {dir:?}); import opencv_stereo_vo as p; p.main(sys.argv[1:])",
                dir = peers
            ));
            cmd.arg(seq).arg("--out").arg(&out).arg("--gt").arg(&gt);
        }
        None => {
            cmd.arg(&script)
                .arg(seq)
                .arg("--out")
                .arg(&out)
                .arg("--gt")
                .arg(&gt);
        }
    }
    let output = cmd.output().map_err(|e| eprintln!("peer: {e}")).ok()?;
    if !output.status.success() {
        eprintln!("peer: {}", String::from_utf8_lossy(&output.stderr).trim());
        return None;
    }
    let text = String::from_utf8_lossy(&output.stdout);
    let line = text.lines().find(|l| l.starts_with("opencv_vo "))?;
    let field = |k: &str| {
        line.split_whitespace()
            .find_map(|kv| kv.strip_prefix(k))
            .and_then(|v| v.parse().ok())
    };
    Some(Figures {
        ms: field("ms_per_frame=")?,
        t_err: field("t_err_pct=")?,
        r_err: field("r_err_deg_per_m=")?,
        lengths: String::new(),
    })
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let arg = |name: &str| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
    };
    let dir = arg("--dir").map_or_else(|| PathBuf::from("target/vo-bench"), PathBuf::from);
    let cases = [
        ("640x480", dir.join("sim_640x480"), 640, 480, 400.0, 200),
        (
            "1241x376",
            dir.join("sim_1241x376"),
            1241,
            376,
            718.856,
            100,
        ),
    ];
    let mut last = None;
    for (name, path, w, h, f, frames) in cases {
        let seq = sequence(&path, w, h, f, frames)?;
        let o = ours(&seq)?;
        println!(
            "# {name} ({} pairs, lengths {} m): ours {:.1} ms/pair, t_err {:.3} %, r_err {:.5} deg/m",
            seq.len(),
            o.lengths,
            o.ms,
            o.t_err,
            o.r_err
        );
        if let Some(peers) = arg("--peer") {
            for (label, threads) in [("OpenCV default threads", None), ("one thread", Some(1))] {
                match peer(peers, &path, threads) {
                    Some(p) => println!(
                        "#   peer ({label}): {:.1} ms/pair, t_err {:.3} %, r_err {:.5} deg/m | ours / peer: time {:.3}, t_err {:.3}, r_err {:.3}",
                        p.ms,
                        p.t_err,
                        p.r_err,
                        o.ms / p.ms,
                        o.t_err / p.t_err,
                        o.r_err / p.r_err
                    ),
                    None => println!("#   peer ({label}): no figures"),
                }
            }
        }
        if name == "640x480" {
            println!("#   target: <= 25 ms/pair (ratio {:.3})", o.ms / 25.0);
            last = Some(o);
        }
    }
    if let Some(o) = last {
        println!(
            "vo ms_per_frame={:.1} t_err_pct={:.3} r_err_deg_per_m={:.5}",
            o.ms, o.t_err, o.r_err
        );
    }
    Ok(())
}
