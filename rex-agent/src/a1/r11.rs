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
//! `r11` runs faster than the camera acquires (every 20 ms, a pair every 5 steps).
//! A pair goes to the odometry in the step it arrives; its motion leaves `latency`
//! steps later, or earlier, in the step the next pair arrives (0: in the same
//! step). Meanwhile the odometry runs on a worker thread
//! ([`OffloadMode::Worker`]), concurrently with the rest of the system and with the
//! camera rendering the next pair; or inside the step ([`OffloadMode::Inline`]).
//! The motions and the instants they leave depend on the latency only, never on
//! where or how fast the odometry ran. A pair the odometry cannot use (blank,
//! textureless, too few matches, no RANSAC consensus) sends nothing and is
//! counted; the next usable pair starts again.

use embodied::{
    Buffers, Fsm, FsmBuildError, Group, In, Memory, Offload, OffloadMode, Out, Subsystem, fsm,
};

use crate::algorithms::vo::{
    Calibration, NoEstimate, StereoOdometry, VoError, VoMotion, VoSettings, VoStats,
};
use crate::math::geometry::{isometry, pose34};
use crate::payload::{AcquireCommand, StereoPair, Transform};

/// What the odometry makes of a pair (the pair's storage comes back with it).
type VoAnswer = (StereoPair, Result<Option<VoMotion>, NoEstimate>);

fn vo_job(vo: &mut StereoOdometry, pair: StereoPair) -> VoAnswer {
    let (w, h) = (pair.width as usize, pair.height as usize);
    let r = vo.process(&pair.left, &pair.right, w, h);
    (pair, r)
}

/// A pair in the odometry: its time and the steps it has waited.
#[derive(Clone, Copy, Debug)]
struct InFlight {
    time: f64,
    waited: u32,
}

/// The odometry state (`odom`).
#[derive(Debug)]
pub struct Odometry {
    vo: Offload<StereoOdometry, StereoPair, VoAnswer>,
    /// Camera to platform (4 × 4).
    mount: [[f64; 4]; 4],
    /// Steps from a pair's arrival to its motion leaving, at most.
    latency: u32,
    /// Time of the last pair processed.
    last_time: Option<f64>,
    in_flight: Option<InFlight>,
    /// Storage for the next pair sent to the odometry.
    spare: StereoPair,
    /// The motion to send in this iteration.
    pub pending: Option<Transform>,
    /// Pairs received.
    pub pairs: u64,
    /// Motions estimated.
    pub motions: u64,
    /// Pairs without an estimate, and the last reason.
    pub no_estimates: u64,
    /// Why the last pair gave no estimate.
    pub last_failure: Option<NoEstimate>,
    /// The odometry itself failed (a panic in it, caught): no more motions.
    pub fault: Option<String>,
}

impl Odometry {
    /// Odometry for a camera with this calibration and mounting, computing inline
    /// with no latency (a pair's motion leaves in the step the pair arrives).
    pub fn new(
        calib: Calibration,
        mount: [[f64; 4]; 4],
        settings: VoSettings,
    ) -> Result<Odometry, VoError> {
        Odometry::pipelined(calib, mount, settings, OffloadMode::Inline, 0)
    }

    /// Odometry running on a worker thread or inline (`mode`), a pair's motion
    /// leaving `latency` steps after the pair arrived, or when the next pair
    /// arrives if that is sooner.
    pub fn pipelined(
        calib: Calibration,
        mount: [[f64; 4]; 4],
        settings: VoSettings,
        mode: OffloadMode,
        latency: u32,
    ) -> Result<Odometry, VoError> {
        Ok(Odometry {
            vo: Offload::new("vo", StereoOdometry::new(calib, settings)?, vo_job, mode),
            mount,
            latency,
            last_time: None,
            in_flight: None,
            spare: StereoPair::default(),
            pending: None,
            pairs: 0,
            motions: 0,
            no_estimates: 0,
            last_failure: None,
            fault: None,
        })
    }

    /// Where the odometry runs.
    pub fn mode(&self) -> OffloadMode {
        self.vo.mode()
    }

    /// The counters, as the odometry's [`VoStats`].
    pub fn stats(&self) -> VoStats {
        VoStats {
            pairs: self.pairs,
            motions: self.motions,
            failures: self.no_estimates,
        }
    }

    /// One step: the motion of the pair in the odometry leaves (`pending`) if it
    /// is due, and a new pair goes in.
    pub fn step(&mut self, pair: Option<&StereoPair>) {
        self.pending = None;
        if let Some(f) = &mut self.in_flight {
            f.waited += 1;
            if pair.is_some() || f.waited >= self.latency {
                self.finish();
            }
        }
        let Some(pair) = pair else { return };
        self.pairs += 1;
        if self.fault.is_some() {
            self.no_estimates += 1;
            return;
        }
        let mut job = std::mem::take(&mut self.spare);
        job.clone_from(pair);
        match self.vo.submit(job) {
            Ok(()) => {
                self.in_flight = Some(InFlight {
                    time: pair.time,
                    waited: 0,
                })
            }
            Err(e) => {
                self.no_estimates += 1;
                self.fault = Some(e.to_string());
            }
        }
        if self.latency == 0 {
            self.finish();
        }
    }

    /// Process a pair and send its motion at once (latency 0), whatever the
    /// latency set.
    pub fn process(&mut self, pair: &StereoPair) {
        self.step(Some(pair));
        if self.in_flight.is_some() {
            self.finish();
        }
    }

    /// Collect the pair in the odometry; `pending` holds the platform's motion
    /// since the previous pair when there is one.
    fn finish(&mut self) {
        let Some(f) = self.in_flight.take() else {
            return;
        };
        let result = match self.vo.collect() {
            Ok(Some((pair, result))) => {
                self.spare = pair;
                result
            }
            Ok(None) => return,
            Err(e) => {
                self.no_estimates += 1;
                self.fault = Some(e.to_string());
                return;
            }
        };
        match result {
            Ok(Some(m)) => {
                self.motions += 1;
                if let Some(from) = self.last_time
                    && f.time.is_finite()
                {
                    // The camera's motion `inv(Tr)`, seen from the platform: E inv(Tr) inv(E).
                    let tr = isometry(&[m.tr[0], m.tr[1], m.tr[2]]);
                    let e = isometry(&[self.mount[0], self.mount[1], self.mount[2]]);
                    let body = pose34(&(e * tr.inverse() * e.inverse()));
                    let t = Transform {
                        matrix: [body[0], body[1], body[2], [0.0, 0.0, 0.0, 1.0]],
                        from,
                        to: f.time,
                    };
                    if t.is_finite() {
                        self.pending = Some(t);
                    }
                }
            }
            Ok(None) => {}
            Err(e) => {
                self.no_estimates += 1;
                self.last_failure = Some(e);
            }
        }
        self.last_time = f.time.is_finite().then_some(f.time);
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

/// `rr_vo` (common part): a new pair goes to the visual odometry; the motion of
/// the pair before it comes out when due.
pub fn rr_vo(m: &mut R11Memory, x: &R11Input) {
    m.odom.step(x.R1.img_lr.fresh());
}

/// `rc`: the motion to `c1` when it comes out of the odometry.
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
    fsm! {
        subsystem R11;
        while vo until false { common <- rr_vo, c1 <- rc, R1 <- rR, memory <- rr_k }
        initial vo;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::vo::VoStats;
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

    /// Runs r11 for 26 iterations with pairs arriving at iterations 0, 5 and 10
    /// (the platform moving between them); the motions sent, with their iteration.
    fn motions_sent(mode: OffloadMode, latency: u32) -> Vec<(u64, Transform)> {
        let c = CameraConfig::default();
        let r = Renderer::new(c.clone(), SceneConfig::default_room()).unwrap();
        let odom = Odometry::pipelined(
            c.calibration(),
            c.mount(),
            VoSettings::default(),
            mode,
            latency,
        )
        .unwrap();
        assert_eq!(odom.mode(), mode);
        let mut m = R11Memory::new(odom, 5);
        let fsm = r11_fsm().unwrap();
        let mut state = fsm.start();
        let mut x = R11Input::default();
        let mut sent = Vec::new();
        for it in 0..26u64 {
            x.R1.img_lr.age();
            if it % 5 == 0 && it <= 10 {
                let k = it as f64 / 5.0;
                let p = pair(
                    &r,
                    [0.5 + 0.05 * k, -0.3, 0.4 + 0.03 * k],
                    k as u64,
                    0.1 * k,
                );
                x.R1.img_lr
                    .deliver(p, embodied::Stamp::new(it, embodied::Time::ZERO));
            }
            let mut y = R11Output::default();
            fsm.activate(&mut state, &mut m, &x, &mut y, |_| {})
                .unwrap();
            if let Some(t) = y.c1.A4x4.written() {
                sent.push((it, *t));
            }
        }
        assert_eq!(
            m.odom.stats(),
            VoStats {
                pairs: 3,
                motions: 2,
                failures: 0
            }
        );
        sent
    }

    #[test]
    fn a_motion_leaves_when_the_next_pair_arrives_or_after_the_latency_wherever_it_ran() {
        let now = motions_sent(OffloadMode::Inline, 0);
        assert_eq!(
            now.iter().map(|s| s.0).collect::<Vec<_>>(),
            [5, 10],
            "latency 0: in the step the pair arrives"
        );
        let late = motions_sent(OffloadMode::Worker, 8);
        assert_eq!(
            late.iter().map(|s| s.0).collect::<Vec<_>>(),
            [10, 18],
            "the second pair's motion when the third arrives, the third's 8 steps after it"
        );
        assert_eq!(
            late,
            motions_sent(OffloadMode::Inline, 8),
            "worker or inline: same run"
        );
        // The same motions, only later.
        let values = |v: &[(u64, Transform)]| v.iter().map(|s| s.1).collect::<Vec<_>>();
        assert_eq!(values(&late), values(&now));
        assert_eq!((late[0].1.from, late[0].1.to), (0.0, 0.1));
    }

    #[test]
    fn matching_and_refining_on_more_threads_gives_the_same_motions() {
        let c = CameraConfig::default();
        let r = Renderer::new(c.clone(), SceneConfig::default_room()).unwrap();
        let motions = |threads| {
            let settings = VoSettings {
                threads,
                ..VoSettings::default()
            };
            let mut vo = StereoOdometry::new(c.calibration(), settings).unwrap();
            (0..4)
                .map(|k| {
                    let k = f64::from(k);
                    let p = pair(&r, [0.5 + 0.06 * k, -0.3, 0.4 + 0.04 * k], 0, k);
                    vo.process(&p.left, &p.right, c.width as usize, c.height as usize)
                })
                .collect::<Vec<_>>()
        };
        let one = motions(1);
        assert!(
            one[1..]
                .iter()
                .all(|m| matches!(m, Ok(Some(m)) if m.matches > 100))
        );
        assert_eq!(motions(2), one);
        assert_eq!(motions(3), one);
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
