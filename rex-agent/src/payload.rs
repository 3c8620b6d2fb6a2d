//! The data that travels through Rex's buffers (names as in `specs/rex.ron`).

use std::fmt;

use serde::{Deserialize, Serialize};

/// A point on the map \[m\].
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Point2 {
    /// x \[m\].
    pub x: f64,
    /// y \[m\].
    pub y: f64,
}

/// A pose on the map: position \[m\] and heading \[rad\].
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose2 {
    /// x \[m\].
    pub x: f64,
    /// y \[m\].
    pub y: f64,
    /// Heading \[rad\].
    pub phi: f64,
}

impl Pose2 {
    /// Whether every component is finite.
    pub fn is_finite(&self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.phi.is_finite()
    }
}

/// A pose measured by the map agent, with the time it describes (it arrives late).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MapPose {
    /// The pose.
    pub pose: Pose2,
    /// Simulation time the pose describes \[s\].
    pub time: f64,
}

/// The platform's state estimate (`q~`, `q~ dot`): `q = (X, Y, φ, θ_1..θ_4)` and its
/// time derivative, and the ground's friction when the estimator estimates it (the
/// paper's `p`).
#[derive(Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct State {
    /// Generalised coordinates `(X, Y, φ, θ_1, θ_2, θ_3, θ_4)`.
    pub q: [f64; 7],
    /// Their rates.
    pub q_dot: [f64; 7],
    /// The ground as estimated (the MHE's; `None` from an estimator that does
    /// not estimate it).
    pub ground: Option<Ground>,
}

/// The ground under the platform as the estimator knows it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Ground {
    /// The friction estimated.
    pub friction: Friction,
    /// Whether the estimate has settled: the platform has driven on this ground
    /// for a while and the estimate no longer moves much. Until then it may be
    /// the estimator's prior, far from the truth.
    pub settled: bool,
}

/// `q (X, Y, φ | θ1 θ2 θ3 θ4) q̇ (…)`, three decimals: short enough for traces.
impl std::fmt::Debug for State {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let part = |f: &mut std::fmt::Formatter<'_>, v: &[f64; 7]| {
            write!(
                f,
                "({:.3}, {:.3}, {:.3} | {:.2} {:.2} {:.2} {:.2})",
                v[0], v[1], v[2], v[3], v[4], v[5], v[6]
            )
        };
        f.write_str("q ")?;
        part(f, &self.q)?;
        f.write_str(" q̇ ")?;
        part(f, &self.q_dot)
    }
}

impl State {
    /// The pose part `(X, Y, φ)`.
    pub fn pose(&self) -> Pose2 {
        Pose2 {
            x: self.q[0],
            y: self.q[1],
            phi: self.q[2],
        }
    }

    /// Whether every component is finite.
    pub fn is_finite(&self) -> bool {
        let friction = self.ground.map_or([0.0; 3], |g| g.friction.to_array());
        self.q
            .iter()
            .chain(&self.q_dot)
            .chain(&friction)
            .all(|v| v.is_finite())
    }
}

/// The ground's friction (in [`State`]).
pub use crate::model::Friction;
/// Wheel torques (`tau`, e1,1 to E1): the platform model's [`Torques`].
pub use crate::model::Torques;

/// A command for the inertial measurement unit (`cmd_E1,1`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum ImuCommand {
    /// Set the integrated heading to `yaw` \[rad\] (align it with the map).
    Reset {
        /// The heading to restart from.
        yaw: f64,
    },
}

/// A reading of the inertial measurement unit (α, α̇ in the paper, planar).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Imu {
    /// Heading integrated from the gyroscope since the last reset \[rad\], in (−π, π].
    pub yaw: f64,
    /// Yaw rate \[rad/s\] (with bias and noise).
    pub yaw_rate: f64,
    /// Body-frame acceleration `(a_x, a_y)` \[m/s²\].
    pub accel: [f64; 2],
}

/// Normal loads measured by the force sensors between the body and each wheel unit \[N\].
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct WheelLoads {
    /// Load per wheel.
    pub load: [f64; 4],
}

/// Wheel encoders: angles and rates.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Encoders {
    /// Angle per wheel \[rad\], quantised to the encoder's resolution.
    pub theta: [f64; 4],
    /// Rate per wheel \[rad/s\], from the counts over the speed window.
    pub rate: [f64; 4],
    /// The platform's clock when the counts were read \[s\] (the time stamp a
    /// real motor controller puts on its messages).
    pub time: f64,
}

/// The acquisition command of the stereo camera (`cmd_R1,1`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct AcquireCommand {
    /// Sequence number of the requested pair.
    pub seq: u64,
}

/// A rectified grayscale stereo pair.
#[derive(Default, PartialEq, Serialize, Deserialize)]
pub struct StereoPair {
    /// Sequence number (from the acquisition command).
    pub seq: u64,
    /// Simulation time of the exposure \[s\].
    pub time: f64,
    /// Width \[px\].
    pub width: u32,
    /// Height \[px\].
    pub height: u32,
    /// Left image, row-major, 8 bits per pixel.
    #[serde(with = "serde_bytes")]
    pub left: Vec<u8>,
    /// Right image.
    #[serde(with = "serde_bytes")]
    pub right: Vec<u8>,
}

impl Clone for StereoPair {
    fn clone(&self) -> Self {
        let mut c = StereoPair::default();
        c.clone_from(self);
        c
    }

    /// Reuses `self`'s image storage (no allocation once it is large enough).
    fn clone_from(&mut self, source: &Self) {
        self.seq = source.seq;
        self.time = source.time;
        self.width = source.width;
        self.height = source.height;
        self.left.clone_from(&source.left);
        self.right.clone_from(&source.right);
    }
}

impl std::fmt::Debug for StereoPair {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "StereoPair {{ seq: {}, time: {:.3}, {}x{} }}",
            self.seq, self.time, self.width, self.height
        )
    }
}

/// A plan from the ontology agent: points on the map to pass in order.
///
/// A plan is sent again, from its first point not yet reached, when the process
/// of `c1` restarted while executing it (see [`Progress`]): `first` is then the
/// index, in the plan as first sent, of `points[0]`, so that fragments keep
/// their numbers and the acknowledgement and outcome the plan's id.
#[derive(Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    /// Plan number.
    pub id: u32,
    /// The points.
    pub points: Vec<Point2>,
    /// Index of `points[0]` in the plan as first sent (0 unless resumed).
    pub first: u32,
}

/// `c1` says who it is (`alive`, every iteration): its incarnation (a new
/// number each time its process starts) and the newest plan it has received.
/// `a2` tells from it that plans it sent were lost: all those not settled
/// when `c1` restarted, and those sent before it first heard from `c1` that
/// `c1` never received.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Alive {
    /// The incarnation.
    pub boot: u64,
    /// The newest plan id received (taken or waiting), 0 for none.
    pub newest: u32,
}

/// How far a plan's execution got: its first `done` fragments were executed to
/// their end (fragment `k` ends at the plan's point `k`). `e11` reports one per
/// fragment completed, and `c1` relays them to `a2`, who resumes the plan after
/// it if `c1` restarts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Progress {
    /// The plan.
    pub plan: u32,
    /// Fragments executed to their end, counted from the plan's first point.
    pub done: u32,
}

/// `Plan 3 [(1.00, 0.00), (1.00, 1.00), … 12 points]`: short enough for traces.
impl std::fmt::Debug for Plan {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Plan {} [", self.id)?;
        if self.first > 0 {
            write!(f, "from point {}: ", self.first)?;
        }
        for (k, p) in self.points.iter().take(3).enumerate() {
            let sep = if k > 0 { ", " } else { "" };
            write!(f, "{sep}({:.2}, {:.2})", p.x, p.y)?;
        }
        match self.points.len() {
            n if n > 3 => write!(f, ", … {n} points]"),
            _ => f.write_str("]"),
        }
    }
}

/// How `c1` answers a plan (`ack` in the paper is a flag: [`AckStatus::Received`] is
/// `ack = false`, sent when a new plan is taken (Algorithm 5); the others are
/// `ack = true`, ready for a new plan (Algorithm 8)).
///
/// `Done` is the paper's early acknowledgement: every fragment was handed over, the
/// platform is still executing the last ones. It does not say the plan was
/// achieved: that comes later, as the plan's [`PlanOutcome`] (`outcome`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum AckStatus {
    /// The plan was taken: not ready for another one yet.
    Received,
    /// Every fragment was handed over for execution (its outcome follows).
    Done,
    /// The plan was refused before execution.
    Refused(String),
    /// Planning or execution stopped (the platform holds its position).
    Failed(String),
}

/// How the execution of a plan ended, as `e11` measured it (`outcome`, sent by
/// `e11` to `c1` and relayed to `a2`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlanOutcome {
    /// The plan.
    pub plan: u32,
    /// `e11`'s stop count when it sent this (fragments handed over with an older
    /// one are stale and refused; see `Fragment::epoch`).
    pub epoch: u32,
    /// What happened.
    pub result: Execution,
}

/// The end of a plan's execution.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Execution {
    /// The platform reached the plan's last point, `error_m` from it (estimated).
    Reached {
        /// Distance to the last point \[m\].
        error_m: f64,
    },
    /// The last fragment ended, but the platform did not come within the
    /// tolerance of its end point.
    Missed {
        /// Distance to the last point when `e11` gave up waiting \[m\].
        error_m: f64,
    },
    /// `e11` stopped the platform (it left the free space, headed out of it, or
    /// strayed too far from its reference): the platform brakes and holds, and
    /// the fragments queued are dropped.
    Stopped(String),
}

impl PlanOutcome {
    /// Whether the plan was achieved.
    pub fn reached(&self) -> bool {
        matches!(self.result, Execution::Reached { .. })
    }
}

impl fmt::Display for Execution {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Execution::Reached { error_m } => {
                write!(f, "reached its last point ({error_m:.3} m from it)")
            }
            Execution::Missed { error_m } => {
                write!(f, "missed its last point by {error_m:.3} m")
            }
            Execution::Stopped(why) => write!(f, "stopped: {why}"),
        }
    }
}

/// `A4x4`: the motion of the platform between two stereo pairs, measured by the
/// visual odometry: `matrix` is the pose of the platform at time `to` in its own
/// frame at time `from` (x forward, y left, z up; row-major), so a platform driving
/// straight ahead has a positive `matrix[0][3]`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Transform {
    /// The homogeneous transform.
    pub matrix: [[f64; 4]; 4],
    /// Time of the earlier pair \[s\].
    pub from: f64,
    /// Time of the later pair \[s\].
    pub to: f64,
}

impl Transform {
    /// The planar part `(dx, dy, dφ)`.
    pub fn planar(&self) -> [f64; 3] {
        let m = &self.matrix;
        [m[0][3], m[1][3], m[1][0].atan2(m[0][0])]
    }

    /// Whether every number is finite.
    pub fn is_finite(&self) -> bool {
        self.matrix.iter().flatten().all(|v| v.is_finite())
            && self.from.is_finite()
            && self.to.is_finite()
    }
}

/// The acknowledgement of a plan (`ack`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Ack {
    /// The plan acknowledged.
    pub plan: u32,
    /// How it ended.
    pub status: AckStatus,
}

impl Ack {
    /// The paper's flag: ready for a new plan.
    pub fn ready(&self) -> bool {
        self.status != AckStatus::Received
    }
}
