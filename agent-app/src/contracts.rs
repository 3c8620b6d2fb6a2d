//! The spec's contracts watched while the system runs: the monitors made from
//! the spec (agent-monitor's), a watch in the executor (every thread of a
//! real-time run, every process of a deployment), and what they found said
//! after the run beside the other figures:
//!
//! ```text
//! contracts_checked=13 contracts_violated=0 contracts_not_evaluable=0
//! ```
//!
//! Each violation is an executor error too ([`agent_core::ExecError::Contract`]),
//! handled by the run's policy (`--on-error`) and recorded on `/errors`.

use agent_core::{ExecError, OnError, RtReport, System};
use agent_monitor::Monitors;
use agent_monitor::live::Live;

use crate::SpecFile;
use crate::error::AppError;
use crate::{output, watch};

/// How many violations are named after the run (all are counted).
const NAMED: usize = 10;

/// The monitors of `spec`'s contracts over `system` (`None`: it states none).
pub(crate) fn live(spec: &SpecFile, system: &System) -> Result<Option<Live>, AppError> {
    if spec.spec.contracts.is_none() {
        return Ok(None);
    }
    let monitors = Monitors::new(&spec.spec)
        .map_err(|e| AppError::invalid(format!("the spec's contracts: {e}")))?;
    Ok(Some(Live::new(monitors, system)))
}

/// Say what the watches found: the violations and the contracts not judged
/// (on standard error, unless `quiet`), and the figure line. Whether every
/// contract was kept (a run that broke one fails).
pub(crate) fn say(live: &Live, quiet: bool) -> bool {
    let verdicts = live.verdicts();
    let monitors = live.monitors();
    if !quiet {
        for v in verdicts.violations.iter().take(NAMED) {
            output::err(format_args!("contract violated: {}", monitors.display(v)));
        }
        if verdicts.count > NAMED as u64 {
            output::err(format_args!("... {} violations in all", verdicts.count));
        }
        for (c, why) in &verdicts.not_judged {
            if let Some(info) = monitors.contract(*c) {
                output::err(format_args!(
                    "contract not judged: {}:{}: {why}",
                    info.kind, info.name
                ));
            }
        }
    }
    if verdicts.undecodable > 0 {
        output::warn(format_args!(
            "{} values did not decode as their shape says: their ranges were not judged",
            verdicts.undecodable
        ));
    }
    output::out(format_args!(
        "contracts_checked={} contracts_violated={} contracts_not_evaluable={}\n",
        verdicts.judged.len(),
        verdicts.contracts_violated(),
        verdicts.not_judged.len()
    ));
    verdicts.count == 0
}

/// The run's own errors, counted and the first ones shown: under `continue` a
/// broken contract is reported apart (the violations) and is not the run's.
pub(crate) fn run_errors(
    report: &RtReport,
    live: Option<&Live>,
    on_error: OnError,
) -> (u64, Vec<String>) {
    if on_error != OnError::Continue {
        return (report.error_count, watch::first_errors(&report.errors));
    }
    let raised = live.map_or(0, |l| l.verdicts().raised);
    let own = report
        .errors
        .iter()
        .filter(|e| !matches!(e, ExecError::Contract { .. }));
    (
        report.error_count.saturating_sub(raised),
        watch::first_errors(own),
    )
}
