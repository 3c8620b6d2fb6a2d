//! Ray casting of the scene into grayscale images.
//!
//! One ray per pixel centre (pixel `(i, j)` at `(u, v) = (i, j)`, see the
//! [module docs](super) for the convention), in `f32`: the floor and the ceiling are planes, the walls
//! the inside of an axis-aligned box, the obstacles axis-aligned boxes tested only
//! where their projected bounding rectangle covers the pixel. Along a row the floor
//! (or ceiling) is seen over one interval of columns, found once a row, where a
//! pixel is a texture fetch at fixed-point coordinates stepped along the row;
//! walls and obstacles are intersected elsewhere only, the walls a block of
//! columns at a time in code the compiler vectorises. Textures are sampled
//! bilinearly.

use super::scene::{SceneConfig, TEXEL_OFFSET, Texture, Textures};
use super::{CameraConfig, CameraPose, Exposure, Side};
use crate::config::{self, ConfigError};

/// What a ray hit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Surface {
    /// The floor (z = 0).
    Floor,
    /// The ceiling.
    Ceiling,
    /// A wall of constant x.
    WallX,
    /// A wall of constant y.
    WallY,
    /// Obstacle `i`, face of constant x.
    ObstacleX(usize),
    /// Obstacle `i`, face of constant y.
    ObstacleY(usize),
    /// Obstacle `i`, top.
    ObstacleTop(usize),
}

/// A ray hit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Distance along the ray (the ray direction's length is the unit).
    pub t: f64,
    /// World point.
    pub point: [f64; 3],
    /// Which surface.
    pub surface: Surface,
}

/// Renders the scene for a camera configuration (both validated on construction and
/// read-only afterwards, so rendering cannot meet a zero-sized image or a NaN focal
/// length).
#[derive(Clone, Debug)]
pub struct Renderer {
    camera: CameraConfig,
    scene: SceneConfig,
    textures: Textures,
    boxes: Vec<[f32; 5]>,
    /// `(x0, y0, x1, y1, height)` of the room.
    room: [f32; 5],
    /// Storage of a blurred exposure: a sub-frame, and the sums of both images.
    scratch: (Vec<u8>, Vec<u16>, Vec<u16>),
}

const CEILING_LEVEL: u8 = 196;

type V3 = [f32; 3];

/// Pixel rectangle `(u0, u1, v0, v1)`, inclusive.
type Rect = (i64, i64, i64, i64);

#[inline]
fn axpy(a: f32, x: V3, y: V3) -> V3 {
    [a * x[0] + y[0], a * x[1] + y[1], a * x[2] + y[2]]
}

impl Renderer {
    /// A renderer; textures are generated from the scene's seed. The camera and the
    /// scene are validated: an invalid one (width 0, focal length ≤ 0 or NaN, an
    /// empty room...) is an error naming the field.
    pub fn new(camera: CameraConfig, scene: SceneConfig) -> Result<Renderer, ConfigError> {
        config::check("camera", &camera)?;
        config::check("scene", &scene)?;
        let textures = Textures::generate(scene.texture_seed);
        let boxes = scene
            .obstacles
            .iter()
            .map(|o| {
                [
                    o.x0 as f32,
                    o.y0 as f32,
                    o.x1 as f32,
                    o.y1 as f32,
                    o.height as f32,
                ]
            })
            .collect();
        let r = &scene.room;
        let room = [
            r.x0 as f32,
            r.y0 as f32,
            r.x1 as f32,
            r.y1 as f32,
            r.height as f32,
        ];
        Ok(Renderer {
            camera,
            scene,
            textures,
            boxes,
            room,
            scratch: Default::default(),
        })
    }

    /// The camera.
    pub fn camera(&self) -> &CameraConfig {
        &self.camera
    }

    /// The scene.
    pub fn scene(&self) -> &SceneConfig {
        &self.scene
    }

    /// Render both images of the pair for the platform at `(x, y, φ)` into `left` and
    /// `right` (resized to `width · height`; their storage is reused).
    pub fn render_pair(&self, body: [f64; 3], left: &mut Vec<u8>, right: &mut Vec<u8>) {
        let n = self.camera.width as usize * self.camera.height as usize;
        left.resize(n, 0);
        right.resize(n, 0);
        self.render(&self.camera.left_pose(body), left);
        self.render(&self.camera.right_pose(body), right);
    }

    /// What the camera delivers for `exposure`: both images rendered along the
    /// platform's motion while the shutter is open (the mean of
    /// [`SensorConfig::sub_frames`](super::SensorConfig::sub_frames) sub-frames,
    /// evenly spaced in the exposure), then developed by the camera's sensor
    /// (noise, gains, vignetting, seeded by `exposure.frame`). With the ideal
    /// sensor and a still platform, this is [`Renderer::render_pair`].
    pub fn capture_pair(&mut self, exposure: &Exposure, left: &mut Vec<u8>, right: &mut Vec<u8>) {
        let sensor = &self.camera.sensor;
        let n = sensor.sub_frames(&self.camera, exposure);
        if n <= 1 {
            self.render_pair(exposure.at(0.5), left, right);
        } else {
            let pixels = self.camera.width as usize * self.camera.height as usize;
            let (mut sub, mut sum_l, mut sum_r) = std::mem::take(&mut self.scratch);
            sub.resize(pixels, 0);
            for sum in [&mut sum_l, &mut sum_r] {
                sum.clear();
                sum.resize(pixels, 0);
            }
            for k in 0..n {
                let body = exposure.at((f64::from(k) + 0.5) / f64::from(n));
                for (pose, sum) in [
                    (self.camera.left_pose(body), &mut sum_l),
                    (self.camera.right_pose(body), &mut sum_r),
                ] {
                    self.render(&pose, &mut sub);
                    for (s, &p) in sum.iter_mut().zip(&sub) {
                        *s += u16::from(p);
                    }
                }
            }
            // n <= 64 sub-frames of at most 255: the sums fit in u16; rounded means.
            let n = n as u16;
            for (img, sum) in [(&mut *left, &sum_l), (&mut *right, &sum_r)] {
                img.clear();
                img.extend(sum.iter().map(|&s| ((s + n / 2) / n) as u8));
            }
            self.scratch = (sub, sum_l, sum_r);
        }
        let sensor = &self.camera.sensor;
        sensor.develop(&self.camera, exposure.frame, Side::Left, left);
        sensor.develop(&self.camera, exposure.frame, Side::Right, right);
    }

    /// The first surface hit by the ray through pixel `(u, v)` (continuous pixel
    /// coordinates; pixel centres are at integers, as in [`CameraConfig::project`]).
    pub fn cast(&self, pose: &CameraPose, u: f64, v: f64) -> Option<Hit> {
        let (cu, cv) = self.camera.principal_point();
        let d = pose.to_world_dir([u - cu, v - cv, self.camera.focal]);
        let c = pose.center.map(|x| x as f32);
        let d32 = d.map(|x| x as f32);
        let (t, surface) = self.trace(c, d32, &self.all_boxes())?;
        let t = f64::from(t);
        Some(Hit {
            t,
            point: [0, 1, 2].map(|i| pose.center[i] + t * d[i]),
            surface,
        })
    }

    fn all_boxes(&self) -> Vec<usize> {
        (0..self.boxes.len()).collect()
    }

    /// Nearest hit along `c + t d`, considering obstacles `active`.
    fn trace(&self, c: V3, d: V3, active: &[usize]) -> Option<(f32, Surface)> {
        let h = self.room[4];
        let (tz, plane) = if d[2] < -1e-9 {
            (-c[2] / d[2], Surface::Floor)
        } else if d[2] > 1e-9 {
            ((h - c[2]) / d[2], Surface::Ceiling)
        } else {
            (f32::INFINITY, Surface::Floor)
        };
        let [x0, y0, x1, y1, _] = self.room;
        let p = axpy(tz, d, c);
        let inside = tz.is_finite() && p[0] >= x0 && p[0] <= x1 && p[1] >= y0 && p[1] <= y1;
        self.trace_from(c, d, (tz, plane, inside), active)
    }

    /// [`Self::trace`] with the floor or ceiling distance `tz` already known, and
    /// whether that hit lies inside the room (then it is nearer than any wall: the
    /// room is convex).
    #[inline(always)]
    fn trace_from(
        &self,
        c: V3,
        d: V3,
        (tz, plane, inside): (f32, Surface, bool),
        active: &[usize],
    ) -> Option<(f32, Surface)> {
        let mut best = tz;
        let mut surface = plane;
        if !inside {
            (best, surface) = self.wall(c, d, (tz, plane));
        }
        if active.is_empty() {
            return best.is_finite().then_some((best, surface));
        }
        let inv = [1.0 / d[0], 1.0 / d[1], 1.0 / d[2]];
        // Plain comparisons (no NaN handling needed: the slab bounds are finite and
        // an infinite inverse gives ±∞, which compares correctly).
        let min = |a: f32, b: f32| if a < b { a } else { b };
        let max = |a: f32, b: f32| if a > b { a } else { b };
        for &i in active {
            let [bx0, by0, bx1, by1, bh] = self.boxes[i];
            let (x_a, x_b) = ((bx0 - c[0]) * inv[0], (bx1 - c[0]) * inv[0]);
            let (y_a, y_b) = ((by0 - c[1]) * inv[1], (by1 - c[1]) * inv[1]);
            let (z_a, z_b) = (-c[2] * inv[2], (bh - c[2]) * inv[2]);
            let (tx, ty, tz) = (min(x_a, x_b), min(y_a, y_b), min(z_a, z_b));
            let enter = max(max(tx, ty), tz);
            let exit = min(min(max(x_a, x_b), max(y_a, y_b)), max(z_a, z_b));
            if enter <= exit && enter > 1e-4 && enter < best {
                best = enter;
                surface = if enter == tx {
                    Surface::ObstacleX(i)
                } else if enter == ty {
                    Surface::ObstacleY(i)
                } else {
                    Surface::ObstacleTop(i)
                };
            }
        }
        best.is_finite().then_some((best, surface))
    }

    /// The nearer of the floor or ceiling hit `(tz, plane)` and the wall the ray
    /// `c + t d` leaves the room through.
    #[inline(always)]
    fn wall(&self, c: V3, d: V3, (tz, plane): (f32, Surface)) -> (f32, Surface) {
        // The wall the ray leaves the room through: compare the two candidate
        // distances without dividing, (X − c_x)/d_x < (Y − c_y)/d_y, then divide once.
        let ((ex, ax), (ey, ay)) = self.exits(c, d);
        let (t_wall, wall) = if ex * ay <= ey * ax {
            (
                if ax > 1e-9 { ex / ax } else { f32::INFINITY },
                Surface::WallX,
            )
        } else {
            (
                if ay > 1e-9 { ey / ay } else { f32::INFINITY },
                Surface::WallY,
            )
        };
        if t_wall < tz {
            (t_wall, wall)
        } else {
            (tz, plane)
        }
    }

    /// The walls of constant x and of constant y that the ray `c + t d` heads
    /// for, each as `(e, a)`: the distance `e ≥ 0` from `c` to it along its axis
    /// and the ray's speed along that axis, `a = |d_x|` or `|d_y|` (the wall is
    /// met at `t = e / a`).
    #[inline(always)]
    fn exits(&self, c: V3, d: V3) -> ((f32, f32), (f32, f32)) {
        let [x0, y0, x1, y1, _] = self.room;
        let x = if d[0] >= 0.0 {
            (x1 - c[0], d[0])
        } else {
            (c[0] - x0, -d[0])
        };
        let y = if d[1] >= 0.0 {
            (y1 - c[1], d[1])
        } else {
            (c[1] - y0, -d[1])
        };
        (x, y)
    }

    /// The grey level of `surface` at world point `p`: its texture, darkened or
    /// lightened by a gain per face (in 256ths) so that neighbouring faces differ.
    #[inline(always)]
    fn shade(&self, p: V3, surface: Surface) -> u8 {
        let t = &self.textures;
        let (texture, a, b, gain) = match surface {
            Surface::Floor => (&t.floor, p[0], p[1], 256),
            Surface::Ceiling => return CEILING_LEVEL,
            Surface::WallX | Surface::WallY => {
                let (a, b, gain) = wall_face(p, surface == Surface::WallX);
                (&t.wall, a, b, gain)
            }
            Surface::ObstacleX(_) => (&t.obstacle, p[1], p[2], 243), // 0.95
            Surface::ObstacleY(_) => (&t.obstacle, p[0], p[2], 205), // 0.8
            Surface::ObstacleTop(_) => (&t.obstacle, p[0], p[1], 282), // 1.1
        };
        ((u32::from(texture.sample(a, b)) * gain) >> 8).min(255) as u8
    }

    /// The pixel rectangle `(u0, u1, v0, v1)` an obstacle can cover, `None` when it
    /// is wholly behind the camera or outside the image.
    ///
    /// The box is clipped against a near plane before projecting: its corners in
    /// front of the plane and the points where its edges cross it bound the part a
    /// ray can hit (the trace ignores hits nearer than that plane), so a box beside
    /// or behind the camera costs nothing instead of covering the whole image.
    fn screen_rect(&self, pose: &CameraPose, i: usize) -> Option<Rect> {
        // Depth of the near plane [m]: below the nearest hit `trace_from` accepts
        // (`t > 1e-4` along a ray whose depth component is the focal length).
        const NEAR: f64 = 1e-3;
        let (w, h) = (i64::from(self.camera.width), i64::from(self.camera.height));
        let [x0, y0, x1, y1, bh] = self.boxes[i].map(f64::from);
        // Corner k has x = [x0, x1][k & 1], y = [y0, y1][(k >> 1) & 1], z = [0, bh][k >> 2].
        let corners: [[f64; 3]; 8] = std::array::from_fn(|k| {
            pose.to_camera([
                if k & 1 == 0 { x0 } else { x1 },
                if k & 2 == 0 { y0 } else { y1 },
                if k & 4 == 0 { 0.0 } else { bh },
            ])
        });
        let (cu, cv) = self.camera.principal_point();
        let f = self.camera.focal;
        let mut rect = (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        );
        let mut add = |c: [f64; 3]| {
            let (u, v) = (f * c[0] / c[2] + cu, f * c[1] / c[2] + cv);
            rect = (rect.0.min(u), rect.1.max(u), rect.2.min(v), rect.3.max(v));
        };
        for c in corners.iter().filter(|c| c[2] >= NEAR) {
            add(*c);
        }
        // The 12 edges: corners differing in one bit.
        for a in 0..8usize {
            for bit in [1usize, 2, 4] {
                let b = a | bit;
                if b == a {
                    continue;
                }
                let (p, q) = (corners[a], corners[b]);
                if (p[2] >= NEAR) != (q[2] >= NEAR) {
                    let s = (NEAR - p[2]) / (q[2] - p[2]);
                    add([0, 1, 2].map(|j| p[j] + s * (q[j] - p[j])));
                }
            }
        }
        if !(rect.0 <= rect.1 && rect.2 <= rect.3) {
            return None; // wholly behind the near plane (or NaN, which the scene excludes)
        }
        // Saturating conversions: a box reaching the near plane projects far outside.
        let (u0, u1) = (
            (rect.0.floor() as i64).saturating_sub(1),
            (rect.1.ceil() as i64).saturating_add(1),
        );
        let (v0, v1) = (
            (rect.2.floor() as i64).saturating_sub(1),
            (rect.3.ceil() as i64).saturating_add(1),
        );
        if u1 < 0 || v1 < 0 || u0 > w - 1 || v0 > h - 1 {
            return None;
        }
        Some((u0.max(0), u1.min(w - 1), v0.max(0), v1.min(h - 1)))
    }

    /// Render the view from `pose` into `out` (`width · height` bytes, row-major).
    ///
    /// The camera has no roll, so its x axis is horizontal and the vertical component
    /// of the ray direction is constant along a row: the floor (or ceiling) distance
    /// is one division per row. When that hit lies inside the room it is nearer than
    /// any wall (the room is convex), so the walls are only intersected where the
    /// floor or ceiling hit falls outside.
    pub fn render(&self, pose: &CameraPose, out: &mut [u8]) {
        let rects: Vec<(usize, Rect)> = (0..self.boxes.len())
            .filter_map(|i| Some((i, self.screen_rect(pose, i)?)))
            .collect();
        render_multiversioned(self, pose, &rects, out);
    }

    /// [`Self::render`] testing obstacle `i` only inside its pixel rectangle, for each
    /// `(i, (u0, u1, v0, v1))` of `rects`.
    ///
    /// Along a row, the floor (or ceiling) hit `c + t_z (d_0 + u r_0)` moves
    /// linearly with the column `u`: the columns where it lies inside the room are
    /// one interval, found once a row, and the floor's texel coordinates are
    /// stepped in fixed point (an integer multiply-add a pixel, the same whichever
    /// path shades the pixel). There, where no obstacle can be seen, a pixel is a
    /// texture fetch; the walls and the obstacles are intersected elsewhere only.
    #[inline(always)]
    fn render_with(&self, pose: &CameraPose, rects: &[(usize, Rect)], out: &mut [u8]) {
        let (w, h) = (self.camera.width as usize, self.camera.height as usize);
        let (cu, cv) = self.camera.principal_point();
        let f = self.camera.focal;
        let step = pose.to_world_dir([1.0, 0.0, 0.0]);
        let (r0, c) = (step.map(|x| x as f32), pose.center.map(|x| x as f32));
        let [x0, y0, x1, y1, room_height] = self.room.map(f64::from);
        let floor = &self.textures.floor;
        // Floor texel coordinates (`Texture::sample_fixed`'s) in 1/2¹⁶ units.
        const FRACTION: f64 = 65_536.0;
        let texels = f64::from(floor.texels_per_m) * 256.0 * FRACTION;
        let offset = f64::from(TEXEL_OFFSET) * FRACTION;
        let mut active: Vec<usize> = Vec::with_capacity(self.boxes.len());
        let mut in_row: Vec<(usize, i64, i64)> = Vec::with_capacity(self.boxes.len());
        for (v, row) in out.chunks_exact_mut(w).take(h).enumerate() {
            let vi = v as i64;
            in_row.clear();
            in_row.extend(
                rects
                    .iter()
                    .filter(|(_, r)| r.2 <= vi && vi <= r.3)
                    .map(|&(i, r)| (i, r.0, r.1)),
            );
            // The ray through the centre of pixel (0, v); column u's is `d0 + u r0`.
            let start = pose.to_world_dir([-cu, v as f64 - cv, f]);
            let d0 = start.map(|x| x as f32);
            // Distance to the floor or the ceiling along this row's rays (r0 is
            // level: the camera has no roll).
            let (tz, plane) = if start[2] < -1e-6 {
                (-pose.center[2] / start[2], Surface::Floor)
            } else if start[2] > 1e-6 {
                ((room_height - pose.center[2]) / start[2], Surface::Ceiling)
            } else {
                (f64::INFINITY, Surface::Floor)
            };
            // The hit at column u is `a + u b` along x and along y.
            let (ax, bx) = (pose.center[0] + tz * start[0], tz * step[0]);
            let (ay, by) = (pose.center[1] + tz * start[1], tz * step[1]);
            let inside = if tz.is_finite() {
                inside_columns(w, [(ax, bx, x0, x1), (ay, by, y0, y1)])
            } else {
                0..0
            };
            let fixed = |a: f64, b: f64| {
                (
                    (a * texels + offset).round() as i64,
                    (b * texels).round() as i64,
                )
            };
            let row_floor = RowFloor {
                u: fixed(ax, bx),
                v: fixed(ay, by),
            };
            let row_plane = (tz as f32, plane);
            // Runs of pixels over which the set of obstacles to test is constant.
            let mut u = 0usize;
            while u < w {
                active.clear();
                let mut run_end = w;
                for &(i, a, b) in &in_row {
                    let (a, b) = (a as usize, b as usize);
                    if a <= u && u <= b {
                        active.push(i);
                        run_end = run_end.min(b + 1);
                    } else if a > u {
                        run_end = run_end.min(a);
                    }
                }
                if active.is_empty() {
                    // Walls, the plane inside the room, walls.
                    let (a, b) = (inside.start.clamp(u, run_end), inside.end.clamp(u, run_end));
                    let rays = Rays { c, d0, r0 };
                    for span in [u..a, b..run_end] {
                        let wall = &mut row[span.clone()];
                        self.walls(&rays, row_plane, &row_floor, span.start, wall);
                    }
                    if plane == Surface::Floor {
                        for (px, k) in row[a..b].iter_mut().zip(a..b) {
                            *px = row_floor.sample(floor, k);
                        }
                    } else {
                        row[a..b].fill(CEILING_LEVEL);
                    }
                } else {
                    for (px, k) in row[u..run_end].iter_mut().zip(u..run_end) {
                        let d = axpy(k as f32, r0, d0);
                        let (tz, plane) = row_plane;
                        let hit = self.trace_from(c, d, (tz, plane, inside.contains(&k)), &active);
                        *px = match hit {
                            Some(hit) => self.shade_hit(c, d, hit, floor, &row_floor, k),
                            None => CEILING_LEVEL,
                        };
                    }
                }
                u = run_end;
            }
        }
    }

    /// The pixels `out` of a row from column `from` on, whose floor (or ceiling)
    /// hit lies outside the room: each is what [`Self::wall`] and
    /// [`Self::shade_hit`] give, bit for bit.
    ///
    /// In blocks of [`BLOCK`] columns, first every ray's wall and texel
    /// coordinates (straight-line code the compiler vectorises: the wall a ray
    /// meets is selected, not branched to), then the texture fetches. A ray that
    /// meets no wall before the floor or the ceiling plane (only at the room's
    /// edges, in rounding), or meets it beyond [`texel_fixed`]'s range, takes the
    /// one-pixel path.
    #[inline(always)]
    fn walls(
        &self,
        rays: &Rays,
        (tz, plane): (f32, Surface),
        row_floor: &RowFloor,
        from: usize,
        out: &mut [u8],
    ) {
        let Rays { c, d0, r0 } = *rays;
        let texture = &self.textures.wall;
        let scale = texture.texels_per_m * 256.0;
        let fixed = |x: f32| texel_fixed(x * scale + TEXEL_OFFSET);
        for (block, out) in out.chunks_mut(BLOCK).enumerate() {
            let first = from + block * BLOCK;
            let mut texel_u = [0u32; BLOCK];
            let mut texel_v = [0u32; BLOCK];
            let mut gain = [0u32; BLOCK];
            let mut direct = [false; BLOCK];
            let n = out.len();
            for (j, (((tu, tv), gain), direct)) in texel_u[..n]
                .iter_mut()
                .zip(&mut texel_v[..n])
                .zip(&mut gain[..n])
                .zip(&mut direct[..n])
                .enumerate()
            {
                let d = axpy((first + j) as f32, r0, d0);
                // `Self::wall`'s arithmetic, selecting instead of branching.
                let ((ex, ax), (ey, ay)) = self.exits(c, d);
                let wall_x = ex * ay <= ey * ax;
                let (e, a) = if wall_x { (ex, ax) } else { (ey, ay) };
                let t = e / a;
                let (along, up, face_gain) = wall_face(axpy(t, d, c), wall_x);
                let ((u, u_valid), (v, v_valid)) = (fixed(along), fixed(up));
                (*tu, *tv, *gain) = (u, v, face_gain);
                *direct = a > 1e-9 && t < tz && u_valid && v_valid;
            }
            for (j, px) in out.iter_mut().enumerate() {
                *px = if direct[j] {
                    let (u, v) = (texel_u[j], texel_v[j]);
                    ((u32::from(texture.sample_fixed(u, v)) * gain[j]) >> 8).min(255) as u8
                } else {
                    let k = first + j;
                    let d = axpy(k as f32, r0, d0);
                    let hit = self.wall(c, d, (tz, plane));
                    self.shade_hit(c, d, hit, &self.textures.floor, row_floor, k)
                };
            }
        }
    }

    /// The grey level of the hit `(t, surface)` of ray `c + t d` through column `k`
    /// (the floor's from the row's fixed-point texel coordinates; a ray that hits
    /// nothing, `t` infinite, sees the ceiling's level).
    #[inline(always)]
    fn shade_hit(
        &self,
        c: V3,
        d: V3,
        (t, surface): (f32, Surface),
        floor: &Texture,
        row_floor: &RowFloor,
        k: usize,
    ) -> u8 {
        match surface {
            Surface::Floor if t.is_finite() => row_floor.sample(floor, k),
            _ if !t.is_finite() => CEILING_LEVEL,
            s => self.shade(axpy(t, d, c), s),
        }
    }
}

/// [`Renderer::render_with`], compiled for AVX2 as well and chosen at run time
/// (the same pixels on any machine: Rust never fuses a multiply and an add).
#[multiversion::multiversion(targets("x86_64+avx2"))]
fn render_multiversioned(r: &Renderer, pose: &CameraPose, rects: &[(usize, Rect)], out: &mut [u8]) {
    r.render_with(pose, rects, out);
}

/// The wall texture's coordinates at world point `p` of a wall of constant x
/// (`wall_x`) or of constant y, and the face's gain in 256ths (0.85 on the walls
/// of constant y, so that walls meeting at a corner differ; their texture is
/// shifted too).
#[inline(always)]
fn wall_face(p: V3, wall_x: bool) -> (f32, f32, u32) {
    if wall_x {
        (p[1], p[2], 256)
    } else {
        (p[0] + 7.3, p[2], 218)
    }
}

/// `x as u32` for `x` in `[2²², 2²⁴)`, and whether `x` is in that range (where
/// [`TEXEL_OFFSET`] keeps the texel coordinates of any point within 160 m of the
/// origin). From the bits: the integer part of such an `x` is its mantissa,
/// shifted by one place below 2²³ (a half's precision there). Integer operations
/// and comparisons, which the compiler vectorises where the saturating
/// conversion stays scalar.
#[inline(always)]
fn texel_fixed(x: f32) -> (u32, bool) {
    // The bits of 2²², 2²³ and 2²⁴ (a negative `x` or a NaN is out of range).
    const TWO_22: u32 = 0x4a80_0000;
    const TWO_23: u32 = 0x4b00_0000;
    const TWO_24: u32 = 0x4b80_0000;
    let (bits, mantissa) = (x.to_bits(), x.to_bits() & 0x007f_ffff);
    let fixed = if bits >= TWO_23 {
        0x0080_0000 + mantissa
    } else {
        0x0040_0000 + (mantissa >> 1)
    };
    (fixed, (TWO_22..TWO_24).contains(&bits))
}

/// Columns of a row whose walls [`Renderer::walls`] computes at once.
const BLOCK: usize = 64;

/// A row's rays: from the camera's centre `c`, through column `k` along `d0 + k r0`.
#[derive(Clone, Copy)]
struct Rays {
    c: V3,
    d0: V3,
    r0: V3,
}

/// A row's floor texel coordinates at column `k`: `start + k · step` along u and
/// along v, in 1/2¹⁶ of [`Texture::sample_fixed`]'s units.
struct RowFloor {
    u: (i64, i64),
    v: (i64, i64),
}

impl RowFloor {
    #[inline(always)]
    fn sample(&self, floor: &Texture, k: usize) -> u8 {
        let k = k as i64;
        let at = |(s, d): (i64, i64)| (s.wrapping_add(k.wrapping_mul(d)) >> 16) as u32;
        floor.sample_fixed(at(self.u), at(self.v))
    }
}

/// The columns of a row of `w` where `lo ≤ a + u b ≤ hi` for each `(a, b, lo, hi)`
/// of `axes`.
fn inside_columns(w: usize, axes: [(f64, f64, f64, f64); 2]) -> std::ops::Range<usize> {
    let (mut from, mut to) = (0.0f64, (w as f64) - 1.0);
    for (a, b, lo, hi) in axes {
        if b == 0.0 {
            if !(lo <= a && a <= hi) {
                return 0..0;
            }
        } else {
            let (p, q) = ((lo - a) / b, (hi - a) / b);
            from = from.max(p.min(q));
            to = to.min(p.max(q));
        }
    }
    // Empty (or NaN, which finite rows exclude).
    if from.partial_cmp(&to).is_none_or(|o| o.is_gt()) {
        return 0..0;
    }
    // Within 0..w: the conversions cannot saturate.
    from.ceil() as usize..to.floor() as usize + 1
}

#[cfg(test)]
mod tests;
