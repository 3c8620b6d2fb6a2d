//! The stereo camera R1, the real receptor of `r1,1`: on each acquisition command it
//! renders a stereo pair at the true pose, and may record the pairs as a KITTI
//! sequence.

use embodied::{
    Buffers, DeviceKind, Driver, DriverContext, DriverError, Group, In, Offload, OffloadMode, Out,
};
use nalgebra::{UnitComplex, Vector2};

use crate::payload::{AcquireCommand, StereoPair};
use crate::world::camera::kitti::SequenceWriter;
use crate::world::camera::{Exposure, Renderer};

/// The acquisition command from `r11`.
#[derive(Debug, Default, Group)]
#[group(peer = VirtualReceptor)]
#[expect(non_snake_case, reason = "the paper's buffer names")]
pub struct CameraFromR11 {
    /// `cmd_R1,1`.
    pub cmd_R11: In<AcquireCommand>,
}

/// The camera's inputs.
#[derive(Debug, Default, Buffers)]
pub struct CameraInput {
    /// From `r11`.
    pub r11: CameraFromR11,
}

/// Images for `r11`.
#[derive(Debug, Default, Group)]
#[group(peer = VirtualReceptor)]
pub struct CameraToR11 {
    /// The stereo pair (`img_lr`).
    pub img_lr: Out<StereoPair>,
}

/// The camera's outputs.
#[derive(Debug, Default, Buffers)]
pub struct CameraOutput {
    /// To `r11`.
    pub r11: CameraToR11,
}

/// A render job: the exposure (the platform's motion while the shutter is open,
/// the frame's number) and the pair to draw into.
type RenderJob = (Exposure, StereoPair);

fn render_job(renderer: &mut Renderer, (exposure, mut pair): RenderJob) -> StereoPair {
    renderer.capture_pair(&exposure, &mut pair.left, &mut pair.right);
    pair
}

/// The simulated stereo camera R1: on an acquisition command it renders a pair at
/// the platform's pose of that instant, and delivers it at its next step (never in
/// the same step, as the paper says). Without a command it sends nothing. The
/// camera's sensor ([`crate::world::camera::SensorConfig`]) blurs the pair by the
/// platform's motion during the exposure (centred on the command's instant) and
/// adds its noise and gains, seeded by the command's sequence number.
///
/// The rendering runs on a worker thread ([`OffloadMode::Worker`], the default)
/// between the command's step and the delivery, concurrently with the rest of the
/// system, or inside the command's step ([`OffloadMode::Inline`]); the pairs and
/// the instants they are delivered are the same either way.
pub struct StereoCamera {
    camera: crate::world::camera::CameraConfig,
    render: Offload<Renderer, RenderJob, StereoPair>,
    /// The pair being rendered: its pose, sequence number and time.
    in_flight: Option<([f64; 3], u64, f64)>,
    /// The pair rendered, to deliver at the next step.
    rendered: Option<StereoPair>,
    /// A rendering failure met outside a step, reported at the next one.
    failure: Option<String>,
    /// Storage for the next pair (recycled through the link).
    spare: StereoPair,
    frames: u64,
    recorder: Option<SequenceWriter>,
    /// The robot of a fleet it rides on ([`super::FleetTruth`]); `None`: the single Rex.
    robot: Option<usize>,
}

impl std::fmt::Debug for StereoCamera {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StereoCamera")
            .field("frames", &self.frames)
            .field("render", &self.render)
            .field("recording", &self.recorder.is_some())
            .finish()
    }
}

impl StereoCamera {
    /// A camera rendering with `renderer` (on a worker thread or inline, `mode`),
    /// looking from the pose in the system's environment, [`Truth`](super::Truth).
    pub fn new(renderer: Renderer, mode: OffloadMode) -> StereoCamera {
        StereoCamera {
            camera: renderer.camera().clone(),
            render: Offload::new("render", renderer, render_job, mode),
            in_flight: None,
            rendered: None,
            failure: None,
            spare: StereoPair::default(),
            frames: 0,
            recorder: None,
            robot: None,
        }
    }

    /// The camera of robot `robot` of a fleet: it looks from the robot's entry
    /// of the fleet's [`super::FleetTruth`].
    pub fn in_fleet(mut self, robot: usize) -> StereoCamera {
        self.robot = Some(robot);
        self
    }

    /// Also write every rendered pair, with its true pose, to a KITTI sequence.
    pub fn record_to(&mut self, writer: SequenceWriter) {
        self.recorder = Some(writer);
    }

    /// Stop recording; returns the writer (call `finish` on it). A pair still being
    /// rendered is finished and written first, so the sequence holds every pair
    /// rendered ([`StereoCamera::frames`]).
    pub fn take_recorder(&mut self) -> Option<SequenceWriter> {
        if let Err(e) = self.finish_render() {
            self.failure = Some(e);
        }
        self.recorder.take()
    }

    /// Wait for the pair in flight, stamp it and record it; it is delivered at the
    /// next step.
    fn finish_render(&mut self) -> Result<(), String> {
        let Some((body, seq, time)) = self.in_flight.take() else {
            return Ok(());
        };
        let mut pair = self
            .render
            .collect()
            .map_err(|e| format!("rendering the stereo pair: {e}"))?
            .ok_or("rendering the stereo pair: the job in flight is lost")?;
        pair.seq = seq;
        pair.time = time;
        pair.width = self.camera.width;
        pair.height = self.camera.height;
        let recorded = match &mut self.recorder {
            Some(w) => w
                .push(time, &self.camera.left_pose(body), &pair.left, &pair.right)
                .map_err(|e| format!("recording the KITTI sequence: {e}")),
            None => Ok(()),
        };
        self.rendered = Some(pair);
        recorded
    }

    /// Where the rendering runs.
    pub fn mode(&self) -> OffloadMode {
        self.render.mode()
    }

    /// Pairs rendered so far.
    pub fn frames(&self) -> u64 {
        self.frames
    }
}

impl Driver for StereoCamera {
    const KIND: DeviceKind = DeviceKind::Receptor;
    type Input = CameraInput;
    type Output = CameraOutput;

    fn step(
        &mut self,
        mut cx: DriverContext<'_>,
        x: &CameraInput,
        y: &mut CameraOutput,
    ) -> Result<(), DriverError> {
        if let Some(e) = self.failure.take() {
            return Err(DriverError::new(e));
        }
        self.finish_render().map_err(DriverError::new)?;
        if let Some(mut pair) = self.rendered.take() {
            // Hand over the pair rendered since the last step; its storage comes
            // back recycled through the link.
            std::mem::swap(y.r11.img_lr.write_recycled(), &mut pair);
            self.spare = pair;
        }
        if let Some(cmd) = x.r11.cmd_R11.fresh() {
            let truth = *super::truth(&mut cx, self.robot)?;
            let s = truth.state;
            let body = [s.x, s.y, s.phi];
            let v = UnitComplex::new(s.phi) * Vector2::new(s.vx, s.vy);
            let velocity = [v.x, v.y, s.omega];
            let exposure = Exposure::moving(body, velocity, self.camera.sensor.exposure_s, cmd.seq);
            self.render
                .submit((exposure, std::mem::take(&mut self.spare)))
                .map_err(|e| DriverError::new(format!("rendering the stereo pair: {e}")))?;
            self.in_flight = Some((body, cmd.seq, truth.time));
            self.frames += 1;
        }
        Ok(())
    }
}
