//! The textured world the stereo camera sees: a room (floor, four walls, ceiling) and
//! box obstacles, with procedural textures rich in blobs and corners.

use serde::{Deserialize, Serialize};

use crate::config::{Invalid, Validate, finite, positive};
use crate::math::rng::Rng;

/// The room: an axis-aligned box `[x0, x1] × [y0, y1] × [0, height]` \[m\].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Room {
    /// Lower x.
    pub x0: f64,
    /// Lower y.
    pub y0: f64,
    /// Upper x.
    pub x1: f64,
    /// Upper y.
    pub y1: f64,
    /// Height of the walls.
    pub height: f64,
}

/// A box standing on the floor.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Obstacle {
    /// Lower x.
    pub x0: f64,
    /// Lower y.
    pub y0: f64,
    /// Upper x.
    pub x1: f64,
    /// Upper y.
    pub y1: f64,
    /// Height.
    pub height: f64,
}

/// What the camera can see.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneConfig {
    /// The room.
    pub room: Room,
    /// Obstacles (the simulation does not collide with them: plans go around them).
    #[serde(default)]
    pub obstacles: Vec<Obstacle>,
    /// Seed of the procedural textures.
    pub texture_seed: u64,
}

impl SceneConfig {
    /// A 12 m × 12 m room, 3 m high, with four pillars and two crates.
    pub fn default_room() -> SceneConfig {
        let b = |x0: f64, y0: f64, x1: f64, y1: f64, height: f64| Obstacle {
            x0,
            y0,
            x1,
            y1,
            height,
        };
        SceneConfig {
            room: Room {
                x0: -6.0,
                y0: -6.0,
                x1: 6.0,
                y1: 6.0,
                height: 3.0,
            },
            obstacles: vec![
                b(-4.6, -4.6, -4.0, -4.0, 2.0),
                b(4.0, -4.6, 4.6, -4.0, 2.0),
                b(-4.6, 4.0, -4.0, 4.6, 2.0),
                b(4.0, 4.0, 4.6, 4.6, 2.0),
                b(-1.0, 4.6, 0.6, 5.4, 0.8),
                b(4.8, -0.8, 5.6, 0.4, 1.2),
            ],
            texture_seed: 2015,
        }
    }
}

impl Validate for SceneConfig {
    fn validate(&self) -> Result<(), Invalid> {
        let r = &self.room;
        for (f, v) in [
            ("room.x0", r.x0),
            ("room.y0", r.y0),
            ("room.x1", r.x1),
            ("room.y1", r.y1),
        ] {
            finite(f, v)?;
        }
        positive("room.x1 - room.x0", r.x1 - r.x0)?;
        positive("room.y1 - room.y0", r.y1 - r.y0)?;
        positive("room.height", r.height)?;
        for (i, o) in self.obstacles.iter().enumerate() {
            for (f, v) in [("x0", o.x0), ("y0", o.y0), ("x1", o.x1), ("y1", o.y1)] {
                finite(&format!("obstacles[{i}].{f}"), v)?;
            }
            positive(&format!("obstacles[{i}].x1 - x0"), o.x1 - o.x0)?;
            positive(&format!("obstacles[{i}].y1 - y0"), o.y1 - o.y0)?;
            positive(&format!("obstacles[{i}].height"), o.height)?;
        }
        Ok(())
    }
}

/// The offset of the fixed-point texel coordinates ([`Texture::sample_fixed`]): a
/// large positive offset keeps them positive (the integer conversion a plain
/// truncation) and leaves a 256th of a texel of `f32` precision.
pub const TEXEL_OFFSET: f32 = 8_388_608.0;

/// A square grayscale texture that repeats, with its scale in texels per metre.
/// Stored row-major with a copy of its first row and column after its last, so
/// that a bilinear sample reads its four texels at fixed offsets.
#[derive(Clone, Debug, PartialEq)]
pub struct Texture {
    log2: u32,
    data: Vec<u8>,
    /// Texels per metre.
    pub texels_per_m: f32,
}

impl Texture {
    /// Side in texels.
    pub fn size(&self) -> usize {
        1 << self.log2
    }

    /// Bilinear sample at `(u, v)` metres (repeating), in 8-bit fixed point.
    #[inline(always)]
    pub fn sample(&self, u: f32, v: f32) -> u8 {
        let scale = self.texels_per_m * 256.0;
        let uf = (u * scale + TEXEL_OFFSET) as u32;
        let vf = (v * scale + TEXEL_OFFSET) as u32;
        self.sample_fixed(uf, vf)
    }

    /// Bilinear sample at texel coordinates in 1/256 of a texel, offset by
    /// [`TEXEL_OFFSET`] (`metres · texels_per_m · 256 + TEXEL_OFFSET`, repeating).
    #[inline(always)]
    pub fn sample_fixed(&self, uf: u32, vf: u32) -> u8 {
        let (fu, fv) = (uf & 255, vf & 255);
        let mask = (1u32 << self.log2) - 1;
        let (u0, v0) = ((uf >> 8) & mask, (vf >> 8) & mask);
        // The four texels: the padding holds the wrapped neighbours, so they are at
        // fixed offsets in one slice (one bounds check).
        let stride = (1usize << self.log2) + 1;
        let i = v0 as usize * stride + u0 as usize;
        let Some(q) = self.data.get(i..i + stride + 2) else {
            return 0; // unreachable: i is at most (size − 1)·(stride + 1)
        };
        let (top, bottom) = (&q[..2], &q[stride..]);
        let at = |x: u8| u32::from(x);
        let top = at(top[0]) * (256 - fu) + at(top[1]) * fu;
        let bottom = at(bottom[0]) * (256 - fu) + at(bottom[1]) * fu;
        ((top * (256 - fv) + bottom * fv) >> 16) as u8
    }

    /// Procedural texture: smooth value noise over several octaves plus scattered
    /// discs with sharp edges (blobs and corners for visual odometry).
    pub fn generate(seed: u64, log2: u32, texels_per_m: f32, mean: f32, discs: usize) -> Texture {
        let size = 1usize << log2;
        let mut rng = Rng::new(seed);
        let mut acc = vec![0.0f32; size * size];
        for (cell, amp) in [(64usize, 38.0f32), (24, 24.0), (8, 14.0), (3, 6.0)] {
            let cells = size.div_ceil(cell);
            let lattice: Vec<f32> = (0..cells * cells)
                .map(|_| rng.uniform() as f32 * 2.0 - 1.0)
                .collect();
            let at = |x: usize, y: usize| lattice[(y % cells) * cells + (x % cells)];
            for y in 0..size {
                let (gy, fy) = (y / cell, (y % cell) as f32 / cell as f32);
                let sy = fy * fy * (3.0 - 2.0 * fy);
                for x in 0..size {
                    let (gx, fx) = (x / cell, (x % cell) as f32 / cell as f32);
                    let sx = fx * fx * (3.0 - 2.0 * fx);
                    let top = at(gx, gy) + sx * (at(gx + 1, gy) - at(gx, gy));
                    let bottom = at(gx, gy + 1) + sx * (at(gx + 1, gy + 1) - at(gx, gy + 1));
                    acc[y * size + x] += amp * (top + sy * (bottom - top));
                }
            }
        }
        for _ in 0..discs {
            let cx = rng.uniform() as f32 * size as f32;
            let cy = rng.uniform() as f32 * size as f32;
            let r = 2.0 + rng.uniform() as f32 * 7.0;
            let level = (rng.uniform() as f32 * 2.0 - 1.0) * 90.0;
            let ri = r.ceil() as i64;
            for dy in -ri..=ri {
                for dx in -ri..=ri {
                    if (dx * dx + dy * dy) as f32 <= r * r {
                        let x = (cx as i64 + dx).rem_euclid(size as i64) as usize;
                        let y = (cy as i64 + dy).rem_euclid(size as i64) as usize;
                        acc[y * size + x] = level;
                    }
                }
            }
        }
        // Row-major with one more row and column, copies of the first: the
        // neighbours of a bilinear sample never wrap.
        let stride = size + 1;
        let data = (0..stride * stride)
            .map(|i| {
                let (x, y) = ((i % stride) % size, (i / stride) % size);
                (mean + acc[y * size + x]).clamp(8.0, 247.0) as u8
            })
            .collect();
        Texture {
            log2,
            data,
            texels_per_m,
        }
    }
}

/// The textures of a scene.
#[derive(Clone, Debug)]
pub struct Textures {
    /// The floor.
    pub floor: Texture,
    /// The walls.
    pub wall: Texture,
    /// The obstacles.
    pub obstacle: Texture,
}

impl Textures {
    /// The textures for `seed`: floor and obstacles darker than the walls, 1 texel
    /// per centimetre.
    pub fn generate(seed: u64) -> Textures {
        Textures {
            floor: Texture::generate(seed, 9, 100.0, 105.0, 900),
            wall: Texture::generate(seed.wrapping_add(1), 9, 100.0, 150.0, 700),
            obstacle: Texture::generate(seed.wrapping_add(2), 8, 100.0, 85.0, 250),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn textures_are_reproducible_and_varied() {
        let a = Texture::generate(1, 7, 100.0, 120.0, 50);
        let b = Texture::generate(1, 7, 100.0, 120.0, 50);
        assert_eq!(a, b);
        let mean = a.data.iter().map(|&x| f64::from(x)).sum::<f64>() / a.data.len() as f64;
        let var = a
            .data
            .iter()
            .map(|&x| (f64::from(x) - mean).powi(2))
            .sum::<f64>()
            / a.data.len() as f64;
        assert!(
            var.sqrt() > 15.0,
            "enough contrast for features: σ = {}",
            var.sqrt()
        );
        // Repeats: the texel at u and at u + size/texels_per_m is the same.
        let period = a.size() as f32 / a.texels_per_m;
        assert_eq!(
            a.sample(0.123, 0.456),
            a.sample(0.123 + period, 0.456 - period)
        );
    }

    #[test]
    fn bad_rooms_are_rejected() {
        let mut s = SceneConfig::default_room();
        assert!(s.validate().is_ok());
        s.room.height = -1.0;
        assert_eq!(s.validate().unwrap_err().0, "room.height");
        let mut s = SceneConfig::default_room();
        s.obstacles[0].x1 = f64::NAN;
        assert_eq!(s.validate().unwrap_err().0, "obstacles[0].x1");
    }
}
