//! The virtual receptor `r11` (the paper's section 3.3): stereo visual odometry on
//! the camera `R1`.
//!
//! One behaviour, `vo`, that never ends; its transition functions (as in
//! `specs/rex.ron`):
//!
//! * `rr_vo` (common part): a new stereo pair goes through the odometry; the motion
//!   of the camera becomes the motion of the platform (through the camera's
//!   mounting) since the previous pair;
//! * `rc` (to `c1`): the transform `A4x4` as soon as a pair is processed;
//! * `rR` (to `R1`): the acquisition command, every `every` steps (video capture);
//! * `rr_k` (memory): counts the steps to the next acquisition.
//!
//! `r11` runs faster than the camera acquires (every 20 ms, a pair every 5 steps):
//! a pair is processed in the step it arrives and its motion leaves at once. A pair
//! the odometry cannot use (blank, textureless, too few matches, no RANSAC
//! consensus) sends nothing and is counted; the next usable pair starts again.

use embodied::{Action, Behaviour, Buffers, Fsm, FsmBuildError, Group, In, Memory, Out, Subsystem};

use crate::a1::payload::{AcquireCommand, StereoPair, Transform};
use crate::algorithms::geometry::{Pose34, compose, invert};
use crate::algorithms::vo::{Calibration, NoEstimate, StereoOdometry, VoError, VoSettings};

/// The odometry state (`odom`).
#[derive(Debug)]
pub struct Odometry {
    vo: StereoOdometry,
    /// Camera to platform (4 × 4).
    mount: [[f64; 4]; 4],
    /// Time of the last pair processed.
    last_time: Option<f64>,
    /// The motion to send in this iteration.
    pub pending: Option<Transform>,
    /// Pairs received.
    pub pairs: u64,
    /// Pairs without an estimate, and the last reason.
    pub no_estimates: u64,
    /// Why the last pair gave no estimate.
    pub last_failure: Option<NoEstimate>,
}

impl Odometry {
    /// Odometry for a camera with this calibration and mounting.
    pub fn new(
        calib: Calibration,
        mount: [[f64; 4]; 4],
        settings: VoSettings,
    ) -> Result<Odometry, VoError> {
        Ok(Odometry {
            vo: StereoOdometry::new(calib, settings)?,
            mount,
            last_time: None,
            pending: None,
            pairs: 0,
            no_estimates: 0,
            last_failure: None,
        })
    }

    /// The odometry.
    pub fn vo(&self) -> &StereoOdometry {
        &self.vo
    }

    /// Process a pair; `pending` holds the platform's motion since the previous
    /// pair when there is one.
    pub fn process(&mut self, pair: &StereoPair) {
        self.pairs += 1;
        self.pending = None;
        let (w, h) = (pair.width as usize, pair.height as usize);
        match self.vo.process(&pair.left, &pair.right, w, h) {
            Ok(Some(m)) => match self.last_time {
                Some(from) if pair.time.is_finite() => {
                    // The camera's motion `inv(Tr)`, seen from the platform: E inv(Tr) inv(E).
                    let tr: Pose34 = [m.tr[0], m.tr[1], m.tr[2]];
                    let e: Pose34 = [self.mount[0], self.mount[1], self.mount[2]];
                    let body = compose(&compose(&e, &invert(&tr)), &invert(&e));
                    let t = Transform {
                        matrix: [body[0], body[1], body[2], [0.0, 0.0, 0.0, 1.0]],
                        from,
                        to: pair.time,
                    };
                    if t.is_finite() {
                        self.pending = Some(t);
                    }
                }
                _ => {}
            },
            Ok(None) => {}
            Err(e) => {
                self.no_estimates += 1;
                self.last_failure = Some(e);
            }
        }
        self.last_time = pair.time.is_finite().then_some(pair.time);
    }
}

/// `r11`'s memory.
#[derive(Debug, Memory)]
pub struct R11Memory {
    /// `k`: steps to the next acquisition.
    pub k: u32,
    /// Acquire every this many steps.
    pub every: u32,
    /// `odom`.
    pub odom: Odometry,
    /// Sequence number of the next acquisition command.
    pub seq: u64,
}

impl R11Memory {
    /// Acquire every `every` steps (the first at the first step).
    pub fn new(odom: Odometry, every: u32) -> R11Memory {
        R11Memory {
            k: 0,
            every: every.max(1),
            odom,
            seq: 0,
        }
    }
}

/// Inputs from the camera.
#[derive(Clone, Debug, Default, Group)]
#[group(peer = RealReceptor)]
pub struct R11FromR1 {
    /// The stereo pair.
    pub img_lr: In<StereoPair>,
}

/// `r11`'s inputs.
#[derive(Clone, Debug, Default, Buffers)]
#[expect(
    non_snake_case,
    reason = "groups are named after their peer component, R1"
)]
pub struct R11Input {
    /// From `R1`.
    pub R1: R11FromR1,
}

/// Outputs to `c1`.
#[derive(Debug, Default, Group)]
#[group(peer = Control)]
#[expect(non_snake_case, reason = "the paper's buffer names")]
pub struct R11ToC1 {
    /// The motion between the last two pairs.
    pub A4x4: Out<Transform>,
}

/// Outputs to the camera.
#[derive(Debug, Default, Group)]
#[group(peer = RealReceptor)]
#[expect(non_snake_case, reason = "the paper's buffer names")]
pub struct R11ToR1 {
    /// The acquisition command.
    pub cmd_R11: Out<AcquireCommand>,
}

/// `r11`'s outputs.
#[derive(Debug, Default, Buffers)]
#[expect(
    non_snake_case,
    reason = "groups are named after their peer component, R1"
)]
pub struct R11Output {
    /// To `c1`.
    pub c1: R11ToC1,
    /// To `R1`.
    pub R1: R11ToR1,
}

/// The virtual receptor `r11`.
#[derive(Subsystem)]
#[subsystem(kind = VirtualReceptor, memory = R11Memory, input = R11Input, output = R11Output)]
pub struct R11;

/// `rr_vo` (common part): visual odometry on a new pair.
pub fn rr_vo(m: &mut R11Memory, x: &R11Input) {
    m.odom.pending = None;
    if let Some(pair) = x.R1.img_lr.fresh() {
        m.odom.process(pair);
    }
}

/// `rc`: the motion to `c1` as soon as a pair is processed.
pub fn rc(m: &R11Memory, _: &R11Input, y: &mut R11ToC1) {
    if let Some(t) = m.odom.pending {
        y.A4x4.set(t);
    }
}

/// `rR`: the acquisition command every `every` steps.
#[expect(
    non_snake_case,
    reason = "the paper's name: the target is a real device"
)]
pub fn rR(m: &R11Memory, _: &R11Input, y: &mut R11ToR1) {
    if m.k == 0 {
        y.cmd_R11.set(AcquireCommand { seq: m.seq });
    }
}

/// `rr_k`: count the steps to the next acquisition.
pub fn rr_k(m: &mut R11Memory, _: &R11Input) {
    if m.k == 0 {
        m.k = m.every - 1;
        m.seq += 1;
    } else {
        m.k -= 1;
    }
}

/// `r11`'s FSM: the single behaviour `vo`.
pub fn r11_fsm() -> Result<Fsm<R11>, FsmBuildError> {
    Fsm::single(Behaviour::while_loop(
        "vo",
        Action::<R11>::new()
            .common(rr_vo)
            .output(|y| &mut y.c1, rc)
            .output(|y| &mut y.R1, rR)
            .memory(rr_k),
        "false",
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::camera::{CameraConfig, Renderer, SceneConfig};

    fn odometry(c: &CameraConfig) -> Odometry {
        Odometry::new(c.calibration(), c.mount(), VoSettings::default()).unwrap()
    }

    fn pair(r: &Renderer, body: [f64; 3], seq: u64, time: f64) -> StereoPair {
        let mut p = StereoPair {
            seq,
            time,
            width: r.camera().width,
            height: r.camera().height,
            ..StereoPair::default()
        };
        r.render_pair(body, &mut p.left, &mut p.right);
        p
    }

    #[test]
    fn a4x4_is_the_platforms_motion_in_its_own_frame() {
        let c = CameraConfig::default();
        let r = Renderer::new(c.clone(), SceneConfig::default_room()).unwrap();
        let mut odom = odometry(&c);
        let (a, b) = ([0.5, -0.3, 0.4], [0.56, -0.26, 0.45]);
        odom.process(&pair(&r, a, 0, 1.0));
        assert!(
            odom.pending.is_none(),
            "the first pair has nothing to compare with"
        );
        odom.process(&pair(&r, b, 1, 1.1));
        let t = odom.pending.expect("a motion");
        assert_eq!((t.from, t.to), (1.0, 1.1));
        // The true motion: b in the frame of a.
        let (s, co) = a[2].sin_cos();
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let truth = [co * dx + s * dy, -s * dx + co * dy, b[2] - a[2]];
        let got = t.planar();
        assert!((got[0] - truth[0]).abs() < 0.005, "{got:?} vs {truth:?}");
        assert!((got[1] - truth[1]).abs() < 0.005, "{got:?} vs {truth:?}");
        assert!((got[2] - truth[2]).abs() < 0.002, "{got:?} vs {truth:?}");
        // Vertical motion, roll and pitch: none.
        assert!(
            t.matrix[2][3].abs() < 0.005 && t.matrix[2][2] > 0.9999,
            "{:?}",
            t.matrix
        );
    }

    #[test]
    fn commands_come_every_k_steps_and_bad_pairs_are_counted() {
        let c = CameraConfig::default();
        let mut m = R11Memory::new(odometry(&c), 5);
        let fsm = r11_fsm().unwrap();
        let mut state = fsm.start();
        let mut x = R11Input::default();
        let mut commanded = Vec::new();
        for it in 0..12 {
            x.R1.img_lr.age();
            if it == 3 {
                // A blank pair.
                let blank = StereoPair {
                    width: c.width,
                    height: c.height,
                    left: vec![0; (c.width * c.height) as usize],
                    right: vec![0; (c.width * c.height) as usize],
                    ..StereoPair::default()
                };
                x.R1.img_lr
                    .deliver(blank, embodied::Stamp::new(it, embodied::Time::ZERO));
            }
            let mut y = R11Output::default();
            fsm.activate(&mut state, &mut m, &x, &mut y, |_| {})
                .unwrap();
            if let Some(cmd) = y.R1.cmd_R11.written() {
                commanded.push((it, cmd.seq));
            }
            assert!(!y.c1.A4x4.is_written(), "no motion from a blank pair");
        }
        assert_eq!(commanded, [(0, 0), (5, 1), (10, 2)]);
        assert_eq!((m.odom.pairs, m.odom.no_estimates), (1, 1));
        assert!(matches!(
            m.odom.last_failure,
            Some(NoEstimate::Textureless { .. })
        ));
    }
}
