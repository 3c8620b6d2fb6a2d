//! Run the tank filling station: the operator agent sends orders, the station agent
//! fills or drains its tank to each level and acknowledges.
//!
//! ```text
//! cargo run --release --example tank -- [--levels 1.2,0.4,nan,1.8] [--seed N] [--trace FILE]
//! cargo run --example tank -- --spec     # the spec of the macro-built twin, as RON
//! ```
//!
//! The last line is `orders_acked=<n>/<n> refused=<n> max_level_error_m=<...>
//! sim_s=<...> realtime_factor=<...>`.

mod agent;
mod twin;

use std::error::Error;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use agent::{Ack, Order, build, default_mission};
use embodied::{ExecConfig, Executor, Observer, Recorder, SubsystemHandle, Time};

struct Args {
    mission: Vec<Order>,
    seed: u64,
    trace: Option<String>,
    spec: bool,
}

fn parse_args() -> Result<Args, String> {
    let mut args = Args {
        mission: default_mission(),
        seed: 7,
        trace: None,
        spec: false,
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let mut value = || it.next().ok_or(format!("{flag} needs a value"));
        match flag.as_str() {
            "--levels" => {
                args.mission = value()?
                    .split(',')
                    .zip(1..)
                    .map(|(s, id)| {
                        s.trim()
                            .parse::<f64>()
                            .map(|level| Order { id, level })
                            .map_err(|e| format!("bad level {s:?}: {e}"))
                    })
                    .collect::<Result<_, _>>()?;
            }
            "--seed" => {
                let v = value()?;
                args.seed = v.parse().map_err(|e| format!("bad seed {v:?}: {e}"))?;
            }
            "--trace" => args.trace = Some(value()?),
            "--spec" => args.spec = true,
            "-h" | "--help" => {
                println!(
                    "usage: tank [--levels L1,L2,...] [--seed N] [--trace FILE] | --spec\n\
                     Runs the filling station until every order is acknowledged.\n\
                     --spec prints the spec exported from the twin written with the macros."
                );
                std::process::exit(0);
            }
            other => return Err(format!("unknown argument {other:?} (try --help)")),
        }
    }
    Ok(args)
}

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> Result<(), Box<dyn Error>> {
    let args = parse_args()?;
    if args.spec {
        let (system, _) = twin::build(args.mission, 0.2, args.seed)?;
        let spec = embodied::spec::export::spec_of("tank", system.info())?;
        print!("{}", embodied::spec::export::to_ron(&spec)?);
        return Ok(());
    }
    let (system, plant) = build(args.mission.clone(), 0.2, args.seed)?;
    println!(
        "tank filling station: {} orders, tank at 0.20 m, seed {}",
        args.mission.len(),
        args.seed
    );
    let (operator, filter) = (plant.operator, plant.filter);
    let wall = Instant::now();
    let (exec, summary) = if let Some(path) = &args.trace {
        let mut exec =
            Executor::with_observer(system, ExecConfig::default(), Recorder::with_text());
        let summary = drive(&mut exec, &args.mission, operator)?;
        std::fs::write(path, exec.observer().trace().to_string())?;
        println!("trace written to {path}");
        (Box::new(exec) as Box<dyn Inspect>, summary)
    } else {
        let mut exec = Executor::new(system, ExecConfig::default());
        let summary = drive(&mut exec, &args.mission, operator)?;
        (Box::new(exec) as Box<dyn Inspect>, summary)
    };
    let wall_s = wall.elapsed().as_secs_f64();
    let sim_s = exec.now().as_secs_f64();
    println!(
        "summary: {} instants, {} implausible gauge readings rejected by r1",
        exec.instants(),
        exec.rejected(&filter)
    );
    println!(
        "orders_acked={}/{} refused={} max_level_error_m={:.4} sim_s={sim_s:.1} realtime_factor={:.0}",
        summary.acked,
        args.mission.len(),
        summary.refused,
        summary.worst,
        sim_s / wall_s.max(1e-9)
    );
    if summary.acked != args.mission.len() {
        return Err("not every order was acknowledged".into());
    }
    Ok(())
}

/// What the example reads back from an executor, whatever its observer.
trait Inspect {
    fn now(&self) -> Time;
    fn instants(&self) -> u64;
    fn rejected(&self, filter: &SubsystemHandle<agent::LevelFilter>) -> u64;
}

impl<O: Observer> Inspect for Executor<O> {
    fn now(&self) -> Time {
        Executor::now(self)
    }
    fn instants(&self) -> u64 {
        self.report().instants
    }
    fn rejected(&self, filter: &SubsystemHandle<agent::LevelFilter>) -> u64 {
        self.memory(filter).map_or(0, |m| m.rejected)
    }
}

struct Summary {
    acked: usize,
    refused: usize,
    worst: f64,
}

/// Run until the operator's mission is over (or an hour of virtual time), printing
/// each acknowledgement as it arrives.
fn drive<O: Observer>(
    exec: &mut Executor<O>,
    mission: &[Order],
    operator: SubsystemHandle<agent::Operator>,
) -> Result<Summary, Box<dyn Error>> {
    let limit = Time::from_nanos(3_600_000_000_000);
    let mut summary = Summary {
        acked: 0,
        refused: 0,
        worst: 0.0,
    };
    while !exec.is_halted(operator.id()) && exec.now() < limit {
        exec.run_for(Duration::from_millis(100))?;
        let acks = exec.memory(&operator).map_or(&[][..], |m| &m.acks[..]);
        for ack in &acks[summary.acked..] {
            let t = exec.now().as_secs_f64();
            match (ack, mission.iter().find(|o| o.id == ack.id())) {
                (Ack::Done { id, level }, Some(o)) => {
                    let err = (level - o.level).abs();
                    summary.worst = summary.worst.max(err);
                    println!(
                        "[{t:>8.2} s] order {id}: level {:.3} m reached (filtered gauge {level:.3} m, error {:.1} mm)",
                        o.level,
                        err * 1e3
                    );
                }
                (Ack::Refused { id, reason }, _) => {
                    summary.refused += 1;
                    println!("[{t:>8.2} s] order {id}: refused: {reason}");
                }
                (Ack::Done { id, .. }, None) => {
                    println!("[{t:>8.2} s] order {id}: acknowledged, but it was never sent")
                }
            }
        }
        summary.acked = acks.len();
    }
    Ok(summary)
}
