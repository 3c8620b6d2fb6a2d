//! `embodied monitor FILE.mcap [--spec FILE]`: the spec's contracts evaluated
//! over a recording ([`embodied::monitor::recording`]). Prints each violation
//! (time, subsystem, contract, values), each contract the recording cannot
//! show and why, then `contracts_checked=N contracts_violated=M
//! contracts_not_evaluable=K`.

use std::path::Path;
use std::process::ExitCode;

use embodied::monitor::Monitors;
use embodied::monitor::recording::{evaluate, needed};
use embodied::record::Recording;

/// Exit 0: no contract violated; 1: some violated; 2: the recording or the
/// spec unreadable (or the spec's contracts not monitorable).
pub(crate) fn run(file: &Path, spec: Option<&Path>) -> ExitCode {
    match evaluate_file(file, spec) {
        Ok(violated) if violated => ExitCode::FAILURE,
        Ok(_) => ExitCode::SUCCESS,
        Err(why) => {
            errln!("embodied monitor: {why}");
            ExitCode::from(2)
        }
    }
}

/// Evaluate and print; `Ok(true)` when a contract is violated.
fn evaluate_file(file: &Path, spec_file: Option<&Path>) -> Result<bool, String> {
    let recording = Recording::open_filtered(file, needed).map_err(|e| e.to_string())?;
    let (name, text) = match spec_file {
        Some(p) => (
            p.display().to_string(),
            std::fs::read_to_string(p).map_err(|e| format!("reading {}: {e}", p.display()))?,
        ),
        None => {
            let recorded = recording.metadata.get("spec");
            let text = recorded.and_then(|m| m.get("text")).ok_or_else(|| {
                format!(
                    "{} holds no spec (metadata `spec`): give one with --spec",
                    file.display()
                )
            })?;
            let name = recorded
                .and_then(|m| m.get("path"))
                .map_or_else(|| "the recorded spec".to_owned(), Clone::clone);
            (name, text.clone())
        }
    };
    let loaded = embodied::spec::load(name.clone(), text).map_err(|report| {
        format!(
            "{name} does not load: {}",
            report
                .findings
                .first()
                .map_or_else(|| "no reason given".to_owned(), |f| f.message.clone())
        )
    })?;
    let mut monitors = Monitors::new(&loaded.spec).map_err(|e| format!("{name}: {e}"))?;
    let report = evaluate(&mut monitors, &recording).map_err(|e| e.to_string())?;
    for v in &report.violations {
        outln!("{}", monitors.display(v));
    }
    for (c, why) in &report.not_evaluable {
        if let Some(info) = monitors.contract(*c) {
            outln!(
                "not evaluable offline: contract={}:{} subsystem={}: {why}",
                info.kind,
                info.name,
                info.subsystem
            );
        }
    }
    let violated = report.contracts_violated();
    outln!(
        "contracts_checked={} contracts_violated={violated} contracts_not_evaluable={}",
        report.checked.len(),
        report.not_evaluable.len()
    );
    Ok(violated > 0)
}
