//! `embodied`: check specifications and draw their diagrams.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand, ValueEnum};
use embodied::spec::diagram::{self, Format, Kind};

/// Check embodied-agent specifications (RON) and draw their diagrams.
#[derive(Parser, Debug)]
#[command(name = "embodied", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Check spec files: names, types, wiring, agent structure, FSMs (with the proof
    /// that arcs are exclusive and complete), periods and deployments.
    ///
    /// Prints every finding with its code and a pointer into the file. Exits with
    /// status 1 if any file has an error, 0 if there are only warnings.
    Check {
        /// Spec files.
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// How to print the findings.
        #[arg(long, value_enum, default_value_t = Style::Human)]
        style: Style,
    },
    /// Draw a diagram of a spec without Graphviz: the FSM of a subsystem (Fig. 5),
    /// the agent structure with its buffers and links (Figs. 2, 4), or the data flow
    /// of the transition functions (Figs. 6-8).
    Diagram {
        /// Spec file.
        file: PathBuf,
        /// What to draw.
        #[arg(long, value_enum)]
        kind: KindArg,
        /// Only this subsystem (for `structure`: only its agent). Default: all.
        #[arg(long, value_name = "NAME")]
        subsystem: Option<String>,
        /// Output format.
        #[arg(long, value_enum, default_value_t = FormatArg::Svg)]
        format: FormatArg,
        /// Write to this file instead of standard output.
        #[arg(short, long, value_name = "PATH")]
        output: Option<PathBuf>,
    },
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Style {
    /// Diagnostics with source excerpts, like rustc.
    Human,
    /// One `file:line:col: severity[code]: message` line per finding.
    Short,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum KindArg {
    /// The FSM of each subsystem: behaviours and arcs labelled with their conditions (Fig. 5).
    Fsm,
    /// The agents: components, buffers and links (Figs. 2 and 4).
    Structure,
    /// The data flow of each behaviour's transition functions (Figs. 6-8).
    Dataflow,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum FormatArg {
    /// Graphviz source, for `dot -Tsvg`.
    Dot,
    /// Mermaid, for Markdown pages (GitHub renders it).
    Mermaid,
    /// A standalone SVG image, laid out without Graphviz.
    Svg,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Command::Check { files, style } => check(&files, style),
        Command::Diagram {
            file,
            kind,
            subsystem,
            format,
            output,
        } => draw(&file, kind, subsystem.as_deref(), format, output.as_deref()),
    }
}

fn check(files: &[PathBuf], style: Style) -> ExitCode {
    let width = std::env::var("COLUMNS")
        .ok()
        .and_then(|c| c.parse().ok())
        .unwrap_or(100);
    let (mut errors, mut warnings, mut unreadable) = (0, 0, 0);
    for path in files {
        match embodied::spec::check_file(path) {
            Err(e) => {
                eprintln!("error: cannot read {}: {e}", path.display());
                unreadable += 1;
            }
            Ok((_, report)) => {
                match style {
                    Style::Human => eprint!("{}", report.render(width)),
                    Style::Short => eprint!("{}", report.short()),
                }
                errors += report.errors();
                warnings += report.warnings();
                let verdict = if report.is_ok() { "ok" } else { "FAILED" };
                println!(
                    "{}: {verdict} ({} errors, {} warnings)",
                    path.display(),
                    report.errors(),
                    report.warnings()
                );
            }
        }
    }
    if files.len() > 1 {
        println!(
            "{} files: {errors} errors, {warnings} warnings{}",
            files.len(),
            if unreadable > 0 {
                format!(", {unreadable} unreadable")
            } else {
                String::new()
            }
        );
    }
    if errors > 0 || unreadable > 0 {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    }
}

fn draw(
    file: &std::path::Path,
    kind: KindArg,
    subsystem: Option<&str>,
    format: FormatArg,
    output: Option<&std::path::Path>,
) -> ExitCode {
    let (spec, report) = match embodied::spec::check_file(file) {
        Ok(x) => x,
        Err(e) => {
            eprintln!("error: cannot read {}: {e}", file.display());
            return ExitCode::FAILURE;
        }
    };
    let Some(spec) = spec else {
        eprint!("{}", report.render(100));
        return ExitCode::FAILURE;
    };
    if !report.is_ok() {
        eprint!("{}", report.render(100));
        eprintln!(
            "warning: {} has errors; the diagram leaves out what does not resolve",
            file.display()
        );
    }
    let kind = match kind {
        KindArg::Fsm => Kind::Fsm,
        KindArg::Structure => Kind::Structure,
        KindArg::Dataflow => Kind::Dataflow,
    };
    let format = match format {
        FormatArg::Dot => Format::Dot,
        FormatArg::Mermaid => Format::Mermaid,
        FormatArg::Svg => Format::Svg,
    };
    let text = match diagram::render(&spec, kind, subsystem, format) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    match output {
        None => {
            print!("{text}");
            ExitCode::SUCCESS
        }
        Some(path) => match std::fs::write(path, text) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("error: cannot write {}: {e}", path.display());
                ExitCode::FAILURE
            }
        },
    }
}
