//! `rex replay FILE.mcap --subsystem NAME`.

use std::path::Path;
use std::process::ExitCode;

use rex_agent::a1::RunSettings;

use crate::{Cli, emit, overrides};

/// `rex replay FILE.mcap --subsystem NAME`.
pub(crate) fn replay(cli: &Cli, file: &Path, subsystem: &str) -> ExitCode {
    use embodied::replay::{Recording, replay_file};
    // The metadata first (no message kept): the settings to build Rex from.
    let head = match Recording::open_filtered(file, |_| false) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("rex replay: {e}");
            return ExitCode::from(2);
        }
    };
    let Some(text) = head.metadata.get("run").and_then(|m| m.get("settings")) else {
        eprintln!(
            "rex replay: {} does not say the settings of its run (not recorded by `rex --record`?)",
            file.display()
        );
        return ExitCode::from(2);
    };
    let mut s: RunSettings = match ron::from_str(text) {
        Ok(s) => s,
        Err(e) => {
            eprintln!(
                "rex replay: the settings recorded in {} do not read: {e}",
                file.display()
            );
            return ExitCode::from(2);
        }
    };
    let here = std::env::current_dir().unwrap_or_default();
    let built = overrides(cli, &mut s)
        .map_err(|e| e.to_string())
        .and_then(|()| s.resolve(&here).map_err(|e| e.to_string()))
        .and_then(|mut config| {
            // A process of a deployment (or a merge of them) recorded it: the
            // deployment's system, and c1's incarnation number as it ran.
            let processes: Vec<_> = head
                .metadata
                .iter()
                .filter(|(name, _)| *name == "process" || name.starts_with("process/"))
                .map(|(_, m)| m)
                .collect();
            if let Some(boot) = processes.iter().find_map(|m| m.get("c1_boot")) {
                config.c1.boot = boot
                    .parse()
                    .map_err(|e| format!("the recorded c1_boot `{boot}`: {e}"))?;
            }
            let built = match processes.iter().find_map(|m| m.get("deployment")) {
                Some(d) => rex_agent::a1::build_deployment(&config, d),
                None => rex_agent::a1::build(&config),
            };
            built
                .map(|(system, _)| (system, config.exec))
                .map_err(|e| e.to_string())
        });
    let (system, exec) = match built {
        Ok(b) => b,
        Err(e) => {
            eprintln!("rex replay: {e}");
            return ExitCode::from(2);
        }
    };
    let start = std::time::Instant::now();
    let result = replay_file(
        file,
        system,
        subsystem,
        rex_agent::record::replay_options(exec),
    );
    let ms = start.elapsed().as_secs_f64() * 1e3;
    match result {
        Ok(r) => {
            emit(format_args!("replay {subsystem}: {r}\n"));
            emit(format_args!(
                "replay_ms={ms:.0} equivalent={}\n",
                if r.is_equivalent() { "yes" } else { "no" }
            ));
            if r.is_equivalent() {
                ExitCode::SUCCESS
            } else {
                ExitCode::FAILURE
            }
        }
        Err(e) => {
            eprintln!("rex replay: {e}");
            ExitCode::from(2)
        }
    }
}
