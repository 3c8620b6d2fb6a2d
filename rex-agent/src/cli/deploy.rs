//! `rex --deployment ... --process NAME` (one process of a deployment) and
//! `rex launch` (all of them): recording in parts and merging them, the
//! development credentials of a secure deployment.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

use embodied::RtConfig;
use embodied::spec::Spec;
use rex_agent::a1::{RexConfig, RunSettings};
use rex_agent::report;

use crate::{Cli, Command, emit, print_recorded, printer, record_options};

/// Set by Ctrl-C (SIGINT) or SIGTERM: a process of a deployment, or the
/// launcher, ends its run cleanly.
static INTERRUPTED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// `--process` (one process of a deployment) or `launch` (all of them).
pub(crate) fn distributed(
    cli: &Cli,
    prepared: &[(RexConfig, Spec, Duration)],
    recorded: &[RunSettings],
) -> ExitCode {
    use rex_agent::run::distributed::{launch, run_process};
    let ([(config, spec, limit)], [settings]) = (prepared, recorded) else {
        eprintln!("rex: a deployment runs one mission at a time (not `all`)");
        return ExitCode::from(2);
    };
    let Some(deployment) = &cli.deployment else {
        eprintln!(
            "rex: `launch` needs `--deployment NAME` (the spec's deployments: {})",
            spec.deployments
                .iter()
                .map(|d| d.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        );
        return ExitCode::from(2);
    };
    let options = embodied::distributed::Options {
        port: cli.port,
        timeout: match cli.wait.map(Duration::try_from_secs_f64) {
            None => None,
            Some(Ok(d)) => Some(d),
            Some(Err(e)) => {
                eprintln!("rex: --wait: {e}");
                return ExitCode::from(2);
            }
        },
        credentials: cli.credentials.clone(),
    };
    let secure = spec.deployment(deployment).is_some_and(|d| d.secure);
    if let Err(e) =
        ctrlc::set_handler(|| INTERRUPTED.store(true, std::sync::atomic::Ordering::Relaxed))
    {
        eprintln!("rex: cannot catch Ctrl-C ({e}); stop with SIGKILL");
    }
    if let Some(process) = &cli.process {
        // `{process}` in the path is this process's name (the launcher's
        // `--record` gives every process its own file so).
        let file = cli
            .record
            .as_ref()
            .map(|f| PathBuf::from(f.to_string_lossy().replace("{process}", process)));
        return match run_process(
            config,
            *limit,
            deployment,
            process,
            &options,
            RtConfig::realtime(),
            file.as_deref()
                .map(|f| (f, record_options(config, spec, settings))),
            &INTERRUPTED,
        ) {
            Ok(run) => {
                let timing = &run.report;
                if !cli.quiet {
                    eprintln!("{timing}");
                }
                if let (Some(file), Some(s)) = (&file, &run.recording) {
                    print_recorded(file, s);
                }
                emit(format_args!(
                    "process={process} rt_priority={} overruns={} executor_errors={} sample_dropped={}\n",
                    if timing.rt_priority() { "yes" } else { "no" },
                    timing.nodes.iter().map(|n| n.overruns).sum::<u64>(),
                    timing.error_count,
                    run.sample_dropped
                ));
                for e in timing.errors.iter().take(5) {
                    eprintln!("rex: {e}");
                }
                if let Err(e) = &run.left {
                    eprintln!("rex: {e}");
                }
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("rex: process `{process}`: {e}");
                // A configuration that cannot run fails again: the launcher does
                // not restart a process that exits with 2.
                if e.is_configuration() {
                    ExitCode::from(2)
                } else {
                    ExitCode::FAILURE
                }
            }
        };
    }
    // The launcher: every process is this program with the same arguments.
    let program = match std::env::current_exe() {
        Ok(p) => p,
        Err(e) => {
            eprintln!("rex: cannot find this program to start the processes: {e}");
            return ExitCode::FAILURE;
        }
    };
    let faults = match &cli.command {
        Some(Command::Launch { kill }) => kill.clone(),
        _ => Vec::new(),
    };
    if let Some((process, _)) = faults
        .iter()
        .find(|(p, _)| !spec_runs_process(spec, deployment, p))
    {
        eprintln!("rex: --kill: deployment `{deployment}` has no process `{process}`");
        return ExitCode::from(2);
    }
    // The processes get the same arguments, without `launch` and its options.
    // Each records its own part (`--record`: `<stem>.<process>.mcap` beside
    // the file), merged into the file when they have ended.
    let parts = cli.record.as_ref().map(|f| record_parts(f));
    let mut args: Vec<String> = Vec::new();
    let mut given = std::env::args().skip(1);
    while let Some(a) = given.next() {
        if a == "--kill" || a == "--record" {
            given.next();
        } else if a != "launch" && !a.starts_with("--kill=") && !a.starts_with("--record=") {
            args.push(a);
        }
    }
    if let Some(pattern) = &parts {
        args.push("--record".into());
        args.push(pattern.to_string_lossy().into_owned());
    }
    // A secure deployment without credentials: a development authority.
    let mut options = options;
    if secure && options.credentials.is_none() {
        let dir = PathBuf::from("target/rex-credentials").join(deployment);
        match dev_credentials(spec, deployment, &dir) {
            Ok(()) => {
                eprintln!(
                    "rex: deployment `{deployment}` is secure: a development authority and certificates in {}",
                    dir.display()
                );
                args.push("--credentials".into());
                args.push(dir.to_string_lossy().into_owned());
                options.credentials = Some(dir);
            }
            Err(e) => {
                eprintln!("rex: {e}");
                return ExitCode::FAILURE;
            }
        }
    }
    if !args.iter().any(|a| a == "--no-report") {
        args.push("--no-report".into());
    }
    let (outcome, launched) = match launch(
        config,
        deployment,
        &options,
        program,
        &args,
        &faults,
        &INTERRUPTED,
        printer(cli.quiet),
    ) {
        Ok(v) => v,
        Err(e) => {
            eprintln!("rex: {e}");
            return ExitCode::FAILURE;
        }
    };
    emit(format_args!("{}", report::summary(&outcome)));
    if let (Some(file), Some(pattern)) = (&cli.record, &parts) {
        merge_parts(file, pattern, spec, deployment);
    }
    if !cli.no_report {
        let dir = cli.out.join(&outcome.mission);
        match report::write(&dir, &outcome, config, spec) {
            Ok(files) => emit(format_args!(
                "report: {} ({} files)\n",
                dir.display(),
                files.len()
            )),
            Err(e) => eprintln!("rex: report: {e}"),
        }
    }
    if !outcome.completed {
        emit(format_args!("the mission did not complete\n"));
    }
    emit(format_args!(
        "{} processes={} restarts={}\n",
        outcome.summary_line(),
        launched.processes,
        launched.restarts
    ));
    if outcome.succeeded() && !INTERRUPTED.load(std::sync::atomic::Ordering::Relaxed) {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}

/// A development authority and certificates for `deployment` in `dir`.
fn dev_credentials(spec: &Spec, deployment: &str, dir: &Path) -> Result<(), String> {
    use embodied::distributed::security::{AccessPolicy, create_dev_authority};
    let policy = AccessPolicy::of(spec, deployment).map_err(|e| e.to_string())?;
    let hosts: Vec<String> = spec
        .deployments
        .iter()
        .filter(|d| d.name == deployment)
        .flat_map(|d| &d.hosts)
        .filter_map(|h| h.address.clone())
        .collect();
    create_dev_authority(dir, &policy, &hosts)
        .map(|_| ())
        .map_err(|e| e.to_string())
}

/// The path of each process's part of a recording to `file`, with
/// `{process}` for the process's name: `<stem>.{process}.mcap` beside it.
fn record_parts(file: &Path) -> PathBuf {
    let stem = file
        .file_stem()
        .map_or_else(|| "record".to_owned(), |s| s.to_string_lossy().into_owned());
    file.with_file_name(format!("{stem}.{{process}}.mcap"))
}

/// Merge the processes' parts of a launched run's recording into `file`.
fn merge_parts(file: &Path, pattern: &Path, spec: &Spec, deployment: &str) {
    let parts: Vec<PathBuf> = spec
        .deployments
        .iter()
        .filter(|d| d.name == deployment)
        .flat_map(|d| d.processes())
        .map(|(_, p, _)| PathBuf::from(pattern.to_string_lossy().replace("{process}", &p.name)))
        .collect();
    match embodied::record::merge(&parts, file) {
        Ok(m) => {
            let size = std::fs::metadata(file).map_or(0, |m| m.len());
            emit(format_args!(
                "record: {} (merged from {} processes: {} messages on {} channels, {:.1} MB{})\n",
                file.display(),
                m.files,
                m.messages,
                m.channels,
                size as f64 / 1e6,
                if m.finished {
                    ""
                } else {
                    "; a process did not finish its part"
                }
            ));
        }
        Err(e) => eprintln!("rex: --record {}: {e}", file.display()),
    }
}

/// Whether `deployment` of `spec` has a process named `process`.
fn spec_runs_process(spec: &Spec, deployment: &str, process: &str) -> bool {
    spec.deployments
        .iter()
        .filter(|d| d.name == deployment)
        .any(|d| d.process(process).is_some())
}
