//! Write a KITTI odometry sequence rendered by the simulated stereo camera.
//!
//! ```text
//! cargo run --release -p rex-agent --example kitti_sequence -- OUT_DIR [--frames N] [--width W --height H --focal F] [--path figure_eight|straight|turn|tour|tour:SEED] [--sensor ideal|realistic:SEED|FILE.ron]
//! ```
//!
//! The camera moves along a scripted path through the shipped room (10 frames per
//! second; the path's speed and turn rate are like the platform's), and each frame's
//! true pose is written to `OUT_DIR/poses.txt`. `--sensor realistic:SEED` images
//! through `SensorConfig::realistic(SEED)` (noise, gains, vignetting, motion blur),
//! as `bench_vo`'s held-out tours are (seeds 11 and 12: tune on others);
//! `--sensor FILE.ron` through a `SensorConfig` of one's own (the `camera.sensor`
//! block of a world file; fields left out are the ideal sensor's).

use std::path::PathBuf;
use std::process::ExitCode;

use rex_agent::config;
use rex_agent::world::WorldConfig;
use rex_agent::world::camera::{Renderer, SensorConfig};
use rex_bench::kitti::{ScriptedPath, write_scripted};

fn main() -> ExitCode {
    match run() {
        Ok(n) => {
            println!("frames={n}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> Result<usize, Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let mut out: Option<PathBuf> = None;
    let mut frames = 200usize;
    let mut path = "figure_eight".to_owned();
    let mut config = WorldConfig::shipped()?;
    while let Some(a) = args.next() {
        let mut value = || args.next().ok_or(format!("{a} needs a value"));
        match a.as_str() {
            "--frames" => frames = value()?.parse()?,
            "--width" => config.camera.width = value()?.parse()?,
            "--height" => config.camera.height = value()?.parse()?,
            "--focal" => config.camera.focal = value()?.parse()?,
            "--path" => path = value()?,
            "--sensor" => {
                config.camera.sensor = match value()?.as_str() {
                    "ideal" => SensorConfig::default(),
                    v if v.ends_with(".ron") => config::load::<SensorConfig>(v.as_ref())?,
                    v => match v.strip_prefix("realistic:").map(str::parse::<u64>) {
                        Some(Ok(seed)) => SensorConfig::realistic(seed),
                        _ => {
                            return Err(format!(
                                "--sensor {v:?}: expected `ideal`, `realistic:SEED` or a FILE.ron"
                            )
                            .into());
                        }
                    },
                }
            }
            "-h" | "--help" => {
                println!(
                    "usage: kitti_sequence OUT_DIR [--frames N] [--width W --height H --focal F] [--path figure_eight|straight|turn|tour|tour:SEED] [--sensor ideal|realistic:SEED|FILE.ron]"
                );
                return Ok(0);
            }
            other if out.is_none() && !other.starts_with('-') => out = Some(PathBuf::from(other)),
            other => return Err(format!("unexpected argument {other:?}").into()),
        }
    }
    // The options may have made the configuration invalid (`--width 0`).
    config::check("command line", &config)?;
    let out = out.ok_or("missing OUT_DIR")?;
    let path: ScriptedPath = path.parse()?;
    let mut renderer = Renderer::new(config.camera.clone(), config.scene.clone())?;
    Ok(write_scripted(&out, &mut renderer, path, frames)?)
}
