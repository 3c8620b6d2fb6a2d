//! What recording costs, and how long a replay takes.
//!
//! The figure-eight mission of the main job, run to its end in the
//! deterministic executor, alternately without an observer and recorded to MCAP
//! (`McapRecorder` with Rex's Foxglove channels, as `rex --record` does), the
//! same number of rounds each, in one process; once with visual odometry (the
//! camera's images: the main job's default) and once without (a run ten times
//! shorter: five times the rounds). Each figure is
//! the ratio of the medians of the whole run's wall time (building the system,
//! running it, and, recorded, closing the file); the rounds' slowest are
//! printed too. Then c1 is replayed against the recording with images, and the
//! replay checked equivalent.
//!
//! The last line:
//! `record_overhead=<with images, recorded/not> mcap_mb_per_min=<file size per
//! simulated minute, with images> replay_ms=<median time to replay c1>`.
//!
//! ```text
//! cargo run --release -p rex-agent --example bench_record [-- ROUNDS]
//! ```

use std::path::Path;
use std::time::{Duration, Instant};

use embodied::NoObserver;
use embodied::record::McapRecorder;
use embodied::replay::replay_file;
use rex_agent::run::{Outcome, RunError, run_mission_observed};
use rex_agent::system::{RexConfig, RunSettings, build};

const LIMIT: Duration = Duration::from_secs(120);

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn max(v: &[f64]) -> f64 {
    v.iter().copied().fold(0.0, f64::max)
}

/// One run, plain: (wall s, outcome).
fn plain(config: &RexConfig) -> Result<(f64, Outcome), RunError> {
    let t = Instant::now();
    let (out, _) = run_mission_observed(config, LIMIT, LIMIT, |_| Ok(NoObserver), |_| {})?;
    Ok((t.elapsed().as_secs_f64(), out))
}

/// One run, recorded to `path`: (wall s, outcome, messages).
fn recorded(
    config: &RexConfig,
    path: &Path,
) -> Result<(f64, Outcome, u64), Box<dyn std::error::Error>> {
    // The previous round's file goes first, outside the timed run: truncating
    // a 160 MB file frees its pages (30-40 ms measured), a cost of this loop,
    // not of recording.
    match std::fs::remove_file(path) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => return Err(e.into()),
        _ => {}
    }
    let t = Instant::now();
    let (out, recorder) = run_mission_observed(
        config,
        LIMIT,
        LIMIT,
        |system| {
            let options = rex_agent::record::options();
            Ok(McapRecorder::create(path, system, options)?)
        },
        |_| {},
    )?;
    let summary = recorder.finish()?;
    Ok((t.elapsed().as_secs_f64(), out, summary.messages))
}

struct Figures {
    ratio: f64,
    mb_per_min: f64,
}

fn measure(
    name: &str,
    config: &RexConfig,
    rounds: usize,
    path: &Path,
) -> Result<Figures, Box<dyn std::error::Error>> {
    let (mut without, mut with) = (Vec::new(), Vec::new());
    let mut sim = 0.0;
    let mut messages = 0;
    for _ in 0..rounds {
        let (w, out) = plain(config)?;
        without.push(w);
        let (r, rec, m) = recorded(config, path)?;
        with.push(r);
        assert_eq!(out.rms(), rec.rms(), "a recorded run is the same run");
        sim = rec.sim_s;
        messages = m;
    }
    let size = std::fs::metadata(path)?.len() as f64 / 1e6;
    let f = Figures {
        ratio: median(&mut with) / median(&mut without),
        mb_per_min: size / (sim / 60.0),
    };
    println!(
        "{name}: wall_s_p50 {:.3} recorded vs {:.3} (max {:.3} vs {:.3}), ratio {:.3}; {messages} messages, {size:.1} MB for {sim:.1} s simulated ({:.1} MB/min)",
        median(&mut with),
        median(&mut without),
        max(&with),
        max(&without),
        f.ratio,
        f.mb_per_min
    );
    Ok(f)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let rounds: usize = std::env::args()
        .nth(1)
        .map(|a| a.parse())
        .transpose()?
        .unwrap_or(3)
        .max(1);
    let settings = RunSettings::default();
    let with_vo: RexConfig = settings.resolve(Path::new("."))?;
    let mut without_vo = with_vo.clone();
    without_vo.visual_odometry = false;
    let dir = std::env::temp_dir();
    let (path_vo, path_plain) = (
        dir.join("bench_record_vo.mcap"),
        dir.join("bench_record.mcap"),
    );
    println!(
        "figure-eight to its end, {} rounds without images and {rounds} with, alternating plain and recorded, medians of the whole run's wall time",
        rounds * 5
    );
    // A run without images is ten times shorter and its overhead a third:
    // five times the rounds, so its median is not one noisy run.
    let no_images = measure(
        "without images (--no-vo)",
        &without_vo,
        rounds * 5,
        &path_plain,
    )?;
    let images = measure("with images", &with_vo, rounds, &path_vo)?;

    let mut replays = Vec::new();
    for _ in 0..rounds {
        let (system, _) = build(&with_vo)?;
        let t = Instant::now();
        let r = replay_file(
            &path_vo,
            system,
            "c1",
            rex_agent::record::replay_options(with_vo.exec),
        )?;
        replays.push(t.elapsed().as_secs_f64() * 1e3);
        if !r.is_equivalent() {
            return Err(format!("the replay of c1 is not equivalent: {r}").into());
        }
    }
    println!(
        "replay of c1 (reading the file, building Rex, replaying): ms p50 {:.0}, max {:.0}; equivalent",
        median(&mut replays.clone()),
        max(&replays)
    );
    println!(
        "record_overhead_no_images={:.3} (aim 1.03) record_overhead_images={:.3} (aim 1.10)",
        no_images.ratio, images.ratio
    );
    println!(
        "record_overhead={:.3} mcap_mb_per_min={:.1} replay_ms={:.0}",
        images.ratio,
        images.mb_per_min,
        median(&mut replays)
    );
    Ok(())
}
