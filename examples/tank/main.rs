//! Run the tank filling station: the operator agent sends orders, the station agent
//! fills or drains its tank to each level and acknowledges. The command line is
//! the application layer's (`embodied::app`): the deterministic run by default,
//! `--realtime`, `--record FILE.mcap`, `replay`, `check`, `diagram`, and the
//! spec's deployment `split` (the station and the operator in two processes
//! over Zenoh) with `launch`.
//!
//! ```text
//! cargo run --release --example tank --features app -- [--levels 1.2,0.4,nan,1.8] [--seed N]
//! cargo run --release --example tank --features app,distributed -- launch --deployment split
//! cargo run --example tank --features app -- --export-spec   # the macro-built twin's spec
//! ```
//!
//! The last line is `orders_acked=<n>/<n> refused=<n> max_level_error_m=<...>
//! sim_s=<...> realtime_factor=<...>`.

mod agent;
mod twin;

use std::process::ExitCode;
use std::time::Duration;

use agent::{Ack, Order, Plant, build, default_mission};
use embodied::app::{
    AppError, Application, Common, End, Program, RunSummary, SpecFile, Target, Verdict, Watcher,
};
use embodied::{Probes, System};
use serde::{Deserialize, Serialize};

/// The spec the station and the operator follow (its deployments place them).
const SPEC: &str = include_str!("../../specs/tank.ron");

/// The tank's own flags.
#[derive(clap::Args, Clone, Debug, Default)]
struct TankFlags {
    /// The levels the operator orders, in metres, comma-separated (`nan` and
    /// levels out of range are refused by the station).
    #[arg(long, global = true, value_name = "L1,L2,...")]
    levels: Option<String>,
    /// The seed of the gauge's noise.
    #[arg(long, global = true, default_value_t = 7)]
    seed: u64,
    /// Print the spec exported from the twin written with the macros, and exit.
    #[arg(long)]
    export_spec: bool,
}

/// One run: the orders (levels as written: a NaN stays one when recorded) and
/// the seed.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct TankConfig {
    levels: Vec<String>,
    seed: u64,
}

impl TankConfig {
    fn mission(&self) -> Result<Vec<Order>, AppError> {
        self.levels
            .iter()
            .zip(1..)
            .map(|(s, id)| {
                s.trim()
                    .parse::<f64>()
                    .map(|level| Order { id, level })
                    .map_err(|e| AppError::invalid(format!("--levels: `{s}`: {e}")))
            })
            .collect()
    }
}

/// What the operator's probe reports: an acknowledgement and when it came.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct Acked {
    t: f64,
    ack: Ack,
}

#[derive(Default)]
struct Tank {
    plant: Option<Plant>,
}

impl Application for Tank {
    type Flags = TankFlags;
    type Config = TankConfig;
    type Seen = Vec<Acked>;

    fn configure(&mut self, flags: &TankFlags, _: &Common) -> Result<Vec<TankConfig>, AppError> {
        if flags.export_spec {
            let (system, _) = twin::build(default_mission(), 0.2, flags.seed)
                .map_err(|e| AppError::Build(Box::new(e)))?;
            let spec = embodied::spec::export::spec_of("tank", system.info())
                .map_err(AppError::invalid)?;
            let text = embodied::spec::export::to_ron(&spec).map_err(AppError::invalid)?;
            embodied::app::emit(format_args!("{text}"));
            std::process::exit(0);
        }
        let levels = match &flags.levels {
            Some(l) => l.split(',').map(str::to_owned).collect(),
            None => default_mission()
                .iter()
                .map(|o| o.level.to_string())
                .collect(),
        };
        let config = TankConfig {
            levels,
            seed: flags.seed,
        };
        config.mission()?;
        Ok(vec![config])
    }

    fn spec(&self, _: &TankConfig) -> Result<SpecFile, AppError> {
        SpecFile::parse("specs/tank.ron", SPEC)
    }

    fn build(&mut self, config: &TankConfig, _: &Target<'_>) -> Result<System, AppError> {
        // Every process builds the whole system (the deployments run all of
        // it); the layer runs each process's part.
        let (system, plant) =
            build(config.mission()?, 0.2, config.seed).map_err(|e| AppError::Build(Box::new(e)))?;
        self.plant = Some(plant);
        Ok(system)
    }

    fn probes(&mut self, probes: &mut Probes<Vec<Acked>>, here: &dyn Fn(&str) -> bool) {
        if let Some(plant) = &self.plant
            && here("c2")
        {
            // The acknowledgements new since the operator's last activation.
            let mut seen = 0;
            probes.subsystem(&plant.operator, move |p| {
                let new: Vec<Acked> = p.memory.acks[seen.min(p.memory.acks.len())..]
                    .iter()
                    .map(|ack| Acked {
                        t: p.time.as_secs_f64(),
                        ack: ack.clone(),
                    })
                    .collect();
                seen = p.memory.acks.len();
                (!new.is_empty()).then_some(new)
            });
        }
    }

    fn watcher(&mut self, config: &TankConfig, common: &Common) -> Box<dyn Watcher<Vec<Acked>>> {
        Box::new(Orders {
            mission: config.mission().unwrap_or_default(),
            acked: Vec::new(),
            refused: 0,
            worst: 0.0,
            quiet: common.quiet,
        })
    }

    fn end(&self, _: &TankConfig) -> End {
        // The operator halts once every order is acknowledged.
        End::halted(["c2"])
    }

    fn limit(&self, _: &TankConfig) -> Duration {
        Duration::from_secs(3600)
    }

    fn check_deployment(&self, config: &TankConfig, deployment: &str) -> Result<(), AppError> {
        // The pump and the gauge share the tank, the system's environment.
        embodied::app::check_together(
            &self.spec(config)?.spec,
            deployment,
            &["E1", "R1"],
            "the pump and the gauge share the tank and must run in one process",
        )
    }

    fn announce(&self, config: &TankConfig) -> Option<String> {
        Some(format!(
            "tank filling station: {} orders, tank at 0.20 m, seed {}",
            config.levels.len(),
            config.seed
        ))
    }
}

/// The operator's acknowledgements, as they arrive.
struct Orders {
    mission: Vec<Order>,
    /// The orders acknowledged (each once, even if a restarted operator
    /// asked again).
    acked: Vec<u32>,
    refused: usize,
    worst: f64,
    quiet: bool,
}

impl Watcher<Vec<Acked>> for Orders {
    fn see(&mut self, acks: Vec<Acked>) {
        for Acked { t, ack } in acks {
            self.take(t, ack);
        }
    }

    fn status(&self) -> Option<String> {
        Some(format!(
            "{}/{} orders acknowledged",
            self.acked.len(),
            self.mission.len()
        ))
    }

    fn judge(&mut self, run: &RunSummary) -> Verdict {
        let layer = run.verdict();
        let all = self.acked.len() == self.mission.len();
        Verdict {
            passed: all && layer.passed,
            text: if all {
                layer.text
            } else {
                format!("{}not every order was acknowledged\n", layer.text)
            },
            line: format!(
                "orders_acked={}/{} refused={} max_level_error_m={:.4} sim_s={:.1} realtime_factor={:.0}",
                self.acked.len(),
                self.mission.len(),
                self.refused,
                self.worst,
                run.last.as_secs_f64(),
                run.realtime_factor()
            ),
        }
    }
}

impl Orders {
    fn take(&mut self, t: f64, ack: Ack) {
        if self.acked.contains(&ack.id()) {
            return;
        }
        self.acked.push(ack.id());
        let line = match (&ack, self.mission.iter().find(|o| o.id == ack.id())) {
            (Ack::Done { id, level }, Some(o)) => {
                let err = (level - o.level).abs();
                self.worst = self.worst.max(err);
                format!(
                    "order {id}: level {:.3} m reached (filtered gauge {level:.3} m, error {:.1} mm)",
                    o.level,
                    err * 1e3
                )
            }
            (Ack::Refused { id, reason }, _) => {
                self.refused += 1;
                format!("order {id}: refused: {reason}")
            }
            (Ack::Done { id, .. }, None) => format!("order {id}: acknowledged, but never sent"),
        };
        if !self.quiet {
            eprintln!("[{t:>8.2} s] {line}");
        }
    }
}

fn main() -> ExitCode {
    embodied::app::main_with(
        Tank::default(),
        Program {
            name: "tank",
            version: env!("CARGO_PKG_VERSION"),
            about: "Run the tank filling station: the operator agent sends orders, the station fills or drains its tank to each level and acknowledges.",
        },
    )
}
