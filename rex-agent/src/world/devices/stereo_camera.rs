//! The stereo camera R1, the real receptor of `r1,1`: on each acquisition command it
//! renders a stereo pair at the true pose, and may record the pairs as a KITTI
//! sequence.

use embodied::{
    Buffers, DeviceKind, Driver, DriverContext, DriverError, Group, In, Out, PortTable, Shape,
};

use super::Truth;
use crate::a1::payload::{AcquireCommand, StereoPair};
use crate::world::camera::Renderer;
use crate::world::camera::kitti::SequenceWriter;

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

/// The simulated stereo camera R1: on an acquisition command it renders a pair at
/// the platform's pose of that instant, and delivers it at its next step (never in
/// the same step, as the paper says). Without a command it sends nothing.
pub struct StereoCamera {
    renderer: Renderer,
    pending: StereoPair,
    has_pending: bool,
    frames: u64,
    recorder: Option<SequenceWriter>,
}

impl std::fmt::Debug for StereoCamera {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StereoCamera")
            .field("frames", &self.frames)
            .field("recording", &self.recorder.is_some())
            .finish()
    }
}

impl StereoCamera {
    /// A camera rendering with `renderer`, looking from the pose in the system's
    /// environment, [`Truth`].
    pub fn new(renderer: Renderer) -> StereoCamera {
        StereoCamera {
            renderer,
            pending: StereoPair::default(),
            has_pending: false,
            frames: 0,
            recorder: None,
        }
    }

    /// Also write every rendered pair, with its true pose, to a KITTI sequence.
    pub fn record_to(&mut self, writer: SequenceWriter) {
        self.recorder = Some(writer);
    }

    /// Stop recording; returns the writer (call `finish` on it).
    pub fn take_recorder(&mut self) -> Option<SequenceWriter> {
        self.recorder.take()
    }

    /// The renderer (camera parameters and scene).
    pub fn renderer(&self) -> &Renderer {
        &self.renderer
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

    fn shape() -> Option<Shape> {
        Some(Shape::of_driver::<Self>())
    }

    fn ports() -> Option<PortTable> {
        Some(PortTable::of::<Self::Input, Self::Output>())
    }

    fn step(
        &mut self,
        mut cx: DriverContext<'_>,
        x: &CameraInput,
        y: &mut CameraOutput,
    ) -> Result<(), DriverError> {
        if self.has_pending {
            // Hand over the pair; its storage comes back recycled through the link.
            std::mem::swap(y.r11.img_lr.write_recycled(), &mut self.pending);
            self.has_pending = false;
        }
        if let Some(cmd) = x.r11.cmd_R11.fresh() {
            let truth = *cx.environment::<Truth>()?;
            let s = truth.state;
            let pair = &mut self.pending;
            let body = [s.x, s.y, s.phi];
            self.renderer
                .render_pair(body, &mut pair.left, &mut pair.right);
            if let Some(w) = &mut self.recorder {
                let pose = self.renderer.camera().left_pose(body);
                w.push(truth.time, &pose, &pair.left, &pair.right)
                    .map_err(|e| DriverError::new(format!("recording the KITTI sequence: {e}")))?;
            }
            pair.seq = cmd.seq;
            pair.time = truth.time;
            pair.width = self.renderer.camera().width;
            pair.height = self.renderer.camera().height;
            self.has_pending = true;
            self.frames += 1;
        }
        Ok(())
    }
}
