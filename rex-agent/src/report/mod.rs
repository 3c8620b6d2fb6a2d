//! The report folder of a Rex run: plots as SVG, the samples as CSV, a summary, and
//! the diagrams of the specification the run followed.
//!
//! | file | what |
//! |---|---|
//! | `summary.txt` | the summary line, the run's choices, counters, acknowledgements |
//! | `samples.csv` | every sample (one per iteration of `e11`) |
//! | `trajectory.svg` | reference, true and estimated paths on the map, with the plan points |
//! | `tracking_error.svg` | distance between the true position and the reference over time |
//! | `torques.svg` | the four wheel torques over time |
//! | `friction.svg` | the estimator's friction of the ground `(μ_x, μ_y, μ_r)` over time (the MHE's; the EKF estimates none) |
//! | `timeline.svg` | `c1`'s behaviour (B1, B2, B3) and the fragment `e11` executes, over time |
//! | `timing.txt` | the timing certificate of the spec, as one process on one host (`embodied check --timing`'s: [`embodied::app::report::timing`]) |
//! | `diagrams/` | every subsystem's FSM (SVG and Mermaid) and data flow, the agents' structure ([`embodied::spec::diagram::render_all`]) |

use std::fmt::Write as _;
use std::io;
use std::path::{Path, PathBuf};

use embodied::app::report::Report;
use embodied::spec::Spec;

use embodied::app::plot::{Marker, PALETTE, Plot, Row, Series, series_over, timeline};
use embodied::app::report::Findings;
use embodied::app::table::Csv;

use crate::run::{Outcome, Sample};
use crate::system::RexConfig;

/// Write the report of `outcome` into `dir` (created if needed); returns the files
/// written.
pub fn write(
    dir: &Path,
    outcome: &Outcome,
    config: &RexConfig,
    spec: &Spec,
) -> io::Result<Vec<PathBuf>> {
    let mut report = Report::create(dir)?;
    report.put("summary.txt", summary(outcome))?;
    report.put("samples.csv", csv(&outcome.samples))?;
    report.put("trajectory.svg", trajectory(outcome, config).to_svg())?;
    report.put("tracking_error.svg", tracking_error(outcome).to_svg())?;
    report.put("torques.svg", torques(outcome).to_svg())?;
    report.put("friction.svg", friction(outcome).to_svg())?;
    report.put("timeline.svg", behaviour_timeline(outcome))?;
    report.spec(spec)?;
    Ok(report.files().to_vec())
}

/// The text of `summary.txt`.
pub fn summary(o: &Outcome) -> String {
    let mut s = String::new();
    let c = &o.counters;
    let _ = writeln!(s, "{}", o.summary_line());
    let _ = writeln!(
        s,
        "planner={} tracker={} estimator={}",
        o.parts[0], o.parts[1], o.parts[2]
    );
    let _ = writeln!(
        s,
        "completed={} sim_s={:.2} wall_s={:.3} estimate_rms_m={:.4}",
        o.completed,
        o.sim_s,
        o.wall_s,
        o.estimate_rms()
    );
    if let Some([mu_long, mu_lat, rolling]) = o.friction_estimate() {
        let _ = writeln!(
            s,
            "friction_estimate mu_long={mu_long:.4} mu_lat={mu_lat:.4} rolling={rolling:.4} (the MHE's, at the end)"
        );
    }
    let _ = writeln!(
        s,
        "fragments planned={} received={} completed={} rejected={} stale={} planner_iterations={} planner_failures={}",
        c.planned,
        c.fragments_received,
        c.fragments_completed,
        c.fragments_rejected,
        c.fragments_stale,
        c.planner_iterations,
        c.planner_failures
    );
    let _ = writeln!(
        s,
        "rejected_measurements={} rejected_poses={} relocalisations={} clamped_torques={} executor_errors={} mocap_delivered={} mocap_dropped={}",
        c.estimator.rejected,
        c.estimator.rejected_poses,
        c.estimator.relocalisations,
        c.clamped_torques,
        c.executor_errors,
        c.mocap.0,
        c.mocap.1
    );
    if c.vo.0 > 0 {
        let _ = writeln!(
            s,
            "vo_pairs={} vo_motions={} vo_no_estimate={}",
            c.vo.0, c.vo.1, c.vo.2
        );
    }
    let t = &c.tracker;
    if t.solves > 0 || t.refused > 0 {
        let _ = writeln!(
            s,
            "tracker_qps={} constrained={} by_clarabel={} failures={} fallbacks={} safe_stops={} refused={}",
            t.solves, t.constrained, t.clarabel, t.failures, t.fallbacks, t.safe_stops, t.refused
        );
    }
    let _ = writeln!(
        s,
        "recovery c1_restarts={} plans_resent={} fragments_repeated={} vo_outages={}",
        c.c1_restarts, c.plans_resent, c.fragments_repeated, c.vo_outages
    );
    let _ = writeln!(s, "faults: {}", faults(o));
    for r in &o.reports {
        let _ = writeln!(s, "{r}");
    }
    for (t, ack) in &o.acks {
        let _ = writeln!(s, "ack t={t:.2} plan={} status={:?}", ack.plan, ack.status);
    }
    for (t, out) in &o.outcomes {
        let _ = writeln!(s, "outcome t={t:.2} plan={} {}", out.plan, out.result);
    }
    s
}

/// Everything that went wrong on the way, whether or not a plan failed of it:
/// `none` or a list.
pub fn faults(o: &Outcome) -> String {
    let c = &o.counters;
    let e = &c.estimator;
    let t = &c.tracker;
    let mut list = Findings::default();
    if e.rejected > 0 || e.relocalisations > 0 {
        list.push(format!(
            "the estimator rejected {} measurements ({} map poses) and relocalised {} times",
            e.rejected, e.rejected_poses, e.relocalisations
        ));
    }
    for (at, why) in &c.stops {
        list.push(format!("e11 stopped the platform at {at:.2} s: {why}"));
    }
    if c.c1_restarts > 0 {
        list.push(format!(
            "c1 restarted {} times: a2 sent {} plans again from where they had got to; {} fragments were executed twice",
            c.c1_restarts, c.plans_resent, c.fragments_repeated
        ));
    }
    for (from, to) in o.vo_outages() {
        list.push(match to {
            Some(to) => format!(
                "visual odometry lost at {from:.2} s, back at {to:.2} s: a1 went on without it"
            ),
            None => format!(
                "visual odometry lost at {from:.2} s, not back before the end: a1 went on without it"
            ),
        });
    }
    list.count(
        c.fragments_stale,
        "fragments refused as handed over before a stop",
    );
    list.count(
        c.fragments_rejected,
        "fragments refused as empty or not finite",
    );
    list.count(c.planner_failures, "planner failures");
    list.count(
        c.plans_out_of_sequence,
        "plans refused by c1 as numbered out of sequence (a plan lost, or a sender that is not a2)",
    );
    list.count(
        c.clamped_torques,
        "torque commands clamped or zeroed by the platform",
    );
    list.count(
        c.watchdog_steps,
        "platform steps at zero torque (command watchdog)",
    );
    list.count(c.executor_errors, "executor errors");
    list.count(t.failures, "tracker solves failed");
    list.count(t.safe_stops, "tracker samples braking after failed solves");
    list.to_string()
}

/// Every sample, a line each, as `samples.csv`.
fn csv(samples: &[Sample]) -> String {
    Csv::new()
        .number("t", 3, |p: &Sample| p.t)
        .numbers(["x", "y", "phi"], 5, |p| p.truth)
        .numbers(["x_est", "y_est", "phi_est"], 5, |p| p.estimate)
        .numbers(["x_ref", "y_ref", "phi_ref", "v_ref", "w_ref"], 5, |p| {
            p.reference.unwrap_or([f64::NAN; 5])
        })
        .number("error", 5, |p| p.error().unwrap_or(f64::NAN))
        .numbers(["tau1", "tau2", "tau3", "tau4"], 4, |p| p.tau)
        .text("behaviour", |p| format!("B{}", p.behaviour + 1))
        .text("plan", |p| {
            p.fragment.map_or(String::new(), |f| f.0.to_string())
        })
        .text("fragment", |p| {
            p.fragment.map_or(String::new(), |f| f.1.to_string())
        })
        .numbers(["mu_long_est", "mu_lat_est", "rolling_est"], 5, |p| {
            p.friction
        })
        .write(samples)
}

fn trajectory(o: &Outcome, config: &RexConfig) -> Plot {
    let mut markers = Vec::new();
    for (i, plan) in config.mission.plans.iter().enumerate() {
        for (k, p) in plan.iter().enumerate() {
            markers.push(Marker {
                at: (p.x, p.y),
                label: format!("{}.{}", i + 1, k + 1),
            });
        }
    }
    Plot {
        title: format!("{}: paths on the map", o.mission),
        x_label: "x [m]".into(),
        y_label: "y [m]".into(),
        equal_aspect: true,
        series: vec![
            Series::of("reference", PALETTE[0], &o.samples, |s| {
                s.fragment.and(s.reference).map(|r| (r[0], r[1]))
            })
            .dashed(),
            Series::of("true", PALETTE[1], &o.samples, |s| {
                Some((s.truth[0], s.truth[1]))
            }),
            Series::of("estimate", PALETTE[2], &o.samples, |s| {
                Some((s.estimate[0], s.estimate[1]))
            }),
        ],
        markers,
    }
}

fn tracking_error(o: &Outcome) -> Plot {
    let err = |s: &Sample| s.error().filter(|_| s.executing).map(|e| (s.t, e));
    Plot {
        title: format!(
            "{}: tracking error (rms {:.1} mm, max {:.1} mm)",
            o.mission,
            o.rms() * 1e3,
            o.max_error() * 1e3
        ),
        x_label: "time [s]".into(),
        y_label: "error [m]".into(),
        series: vec![
            Series::of("|true - reference|", PALETTE[1], &o.samples, err),
            Series::of("|estimate - true|", PALETTE[2], &o.samples, |s| {
                Some((s.t, s.estimate_error()))
            })
            .dashed(),
        ],
        ..Plot::default()
    }
}

fn friction(o: &Outcome) -> Plot {
    Plot {
        title: format!("{}: friction of the ground ({})", o.mission, o.parts[2]),
        x_label: "time [s]".into(),
        y_label: "estimate".into(),
        series: series_over(["mu_long", "mu_lat", "rolling"], &o.samples, |s| {
            (s.t, s.friction)
        }),
        ..Plot::default()
    }
}

fn torques(o: &Outcome) -> Plot {
    let names = [
        "tau1 front-left",
        "tau2 rear-left",
        "tau3 front-right",
        "tau4 rear-right",
    ];
    Plot {
        title: format!("{}: wheel torques", o.mission),
        x_label: "time [s]".into(),
        y_label: "torque [N m]".into(),
        series: series_over(names, &o.samples, |s| (s.t, s.tau)),
        ..Plot::default()
    }
}

fn behaviour_timeline(o: &Outcome) -> String {
    const COLOURS: [&str; 3] = ["#7f7f7f", "#1f77b4", "#2ca02c"];
    let end = o.samples.last().map_or(0.0, |s| s.t);
    let behaviours = o.samples.iter().map(|s| (s.t, s.behaviour));
    let c1 = Row::of_changes("c1", behaviours, end, |&b| {
        (format!("B{}", b + 1), COLOURS[b as usize % 3])
    });
    let fragments = o.samples.iter().map(|s| (s.t, s.fragment));
    let e11 = Row::of_changes("e11", fragments, end, |f| match f {
        Some((p, i)) => (format!("{p}.{i}"), PALETTE[(*i as usize) % 2 * 3]),
        None => ("hold".into(), "#bbbbbb"),
    });
    let acks = o.acks.iter().map(|(t, a)| (*t, format!("ack {}", a.plan)));
    timeline(
        &format!(
            "{}: behaviours of c1, fragments of e11 (plan.index), acknowledgements",
            o.mission
        ),
        &[c1, e11, Row::of_instants("a2", acks, end, "#d62728")],
        end,
    )
}
