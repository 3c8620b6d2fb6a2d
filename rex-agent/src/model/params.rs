//! Parameters of the skid-steer platform and of the ground it drives on.
//!
//! Conventions (reference notes `control.md` §1.1): body frame at the centre of mass,
//! x forward, y left; wheels 1 front-left, 2 rear-left, 3 front-right, 4 rear-right,
//! contact points `d_1 = (a, c)`, `d_2 = (-b, c)`, `d_3 = (a, -c)`, `d_4 = (-b, -c)`.

use serde::{Deserialize, Serialize};

use crate::config::{Invalid, Validate, finite, non_negative, positive};

/// Mass, geometry and drive limits of the platform.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlatformParams {
    /// Mass \[kg\], wheels included.
    pub mass: f64,
    /// Yaw inertia about the centre of mass \[kg m²\].
    pub inertia: f64,
    /// Effective wheel rolling radius r \[m\].
    pub wheel_radius: f64,
    /// Half track c: centre of mass to the left/right wheel plane \[m\].
    pub half_track: f64,
    /// a: centre of mass to the front axle \[m\].
    pub front: f64,
    /// b: centre of mass to the rear axle \[m\].
    pub rear: f64,
    /// Spin inertia of one wheel with the reflected rotor J_w \[kg m²\].
    pub wheel_inertia: f64,
    /// Height of the centre of mass \[m\] (load transfer onto the force sensors).
    pub cog_height: f64,
    /// Gravity \[m/s²\].
    pub gravity: f64,
    /// Smoothing of the friction sign, `sg(s) = 2/π atan(k_s s)` \[s/m\].
    pub sign_smoothing: f64,
    /// Torque bound per wheel \[N m\].
    pub torque_max: f64,
    /// Wheel speed at which the motor torque falls to zero \[rad/s\].
    pub wheel_speed_max: f64,
    /// Bound on the forward speed used by controllers \[m/s\].
    pub speed_max: f64,
    /// Bound on the yaw rate used by controllers \[rad/s\].
    pub yaw_rate_max: f64,
}

impl PlatformParams {
    /// The 40 kg platform of the peers (`casadi_nmpc.py`, notes §1.5).
    pub fn peer_default() -> PlatformParams {
        PlatformParams {
            mass: 40.0,
            inertia: 2.0,
            wheel_radius: 0.10,
            half_track: 0.25,
            front: 0.20,
            rear: 0.20,
            wheel_inertia: 0.01,
            cog_height: 0.15,
            gravity: 9.81,
            sign_smoothing: 20.0,
            torque_max: 10.0,
            wheel_speed_max: 30.0,
            speed_max: 1.5,
            yaw_rate_max: 2.0,
        }
    }

    /// Contact points `d_i = (x, y)` of the four wheels in the body frame.
    pub fn contacts(&self) -> [[f64; 2]; 4] {
        let (a, b, c) = (self.front, self.rear, self.half_track);
        [[a, c], [-b, c], [a, -c], [-b, -c]]
    }

    /// Static normal load of each wheel \[N\].
    pub fn static_loads(&self) -> [f64; 4] {
        let (a, b) = (self.front, self.rear);
        let front = self.mass * self.gravity * b / (2.0 * (a + b));
        let rear = self.mass * self.gravity * a / (2.0 * (a + b));
        [front, rear, front, rear]
    }

    /// Effective translational mass of the reduced model: `m + 4 J_w / r²`.
    pub fn effective_mass(&self) -> f64 {
        self.mass + 4.0 * self.wheel_inertia / self.wheel_radius.powi(2)
    }
}

impl Validate for PlatformParams {
    fn validate(&self) -> Result<(), Invalid> {
        positive("mass", self.mass)?;
        positive("inertia", self.inertia)?;
        positive("wheel_radius", self.wheel_radius)?;
        positive("half_track", self.half_track)?;
        // Both positive: every wheel carries a share of the weight (the
        // prediction models divide by the static loads).
        positive("front", self.front)?;
        positive("rear", self.rear)?;
        positive("wheel_inertia", self.wheel_inertia)?;
        non_negative("cog_height", self.cog_height)?;
        positive("gravity", self.gravity)?;
        positive("sign_smoothing", self.sign_smoothing)?;
        positive("torque_max", self.torque_max)?;
        positive("wheel_speed_max", self.wheel_speed_max)?;
        positive("speed_max", self.speed_max)?;
        positive("yaw_rate_max", self.yaw_rate_max)
    }
}

/// The slip parameters `p = (x_0, μ_s, μ_l)` of the reduced model (§1.3): ICR offset,
/// longitudinal rolling resistance, lateral sliding friction.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SlipParams {
    /// x-coordinate of the instantaneous centre of rotation \[m\].
    pub x_icr: f64,
    /// Longitudinal rolling resistance μ_s.
    pub mu_s: f64,
    /// Lateral sliding friction μ_l.
    pub mu_l: f64,
}

impl Default for SlipParams {
    /// [`SlipParams::NOMINAL`].
    fn default() -> Self {
        SlipParams::NOMINAL
    }
}

impl SlipParams {
    /// The peers' nominal values (0.03, 0.05, 0.5).
    pub const NOMINAL: SlipParams = SlipParams {
        x_icr: 0.03,
        mu_s: 0.05,
        mu_l: 0.5,
    };

    /// As an array `[x_0, μ_s, μ_l]`.
    pub fn to_array(self) -> [f64; 3] {
        [self.x_icr, self.mu_s, self.mu_l]
    }
}

impl Validate for SlipParams {
    fn validate(&self) -> Result<(), Invalid> {
        finite("x_icr", self.x_icr)?;
        non_negative("mu_s", self.mu_s)?;
        non_negative("mu_l", self.mu_l)
    }
}

/// The friction of a ground as the lateral-slip model ([`super::Lateral`]) and
/// its estimator know it: the three coefficients of a [`Surface`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Friction {
    /// Longitudinal friction μ_x: the traction a wheel can transmit is `μ_x N`.
    pub mu_long: f64,
    /// Lateral friction μ_y.
    pub mu_lat: f64,
    /// Rolling resistance coefficient μ_r.
    pub rolling: f64,
}

impl Friction {
    /// Concrete's (μ_x 0.8, μ_y 0.6, rolling 0.02): the lateral-slip MHE's
    /// default prior (Rex's starts from its cautious ground instead).
    pub const CONCRETE: Friction = Friction {
        mu_long: 0.8,
        mu_lat: 0.6,
        rolling: 0.02,
    };

    /// As an array `[μ_x, μ_y, μ_r]`.
    pub fn to_array(self) -> [f64; 3] {
        [self.mu_long, self.mu_lat, self.rolling]
    }

    /// From an array `[μ_x, μ_y, μ_r]`.
    pub fn from_array(a: [f64; 3]) -> Friction {
        Friction {
            mu_long: a[0],
            mu_lat: a[1],
            rolling: a[2],
        }
    }

    /// The largest relative difference of the two friction coefficients
    /// (μ_x, μ_y) from `truth`'s.
    pub fn friction_error(&self, truth: &Friction) -> f64 {
        let rel = |a: f64, b: f64| (a - b).abs() / b.abs().max(1e-9);
        rel(self.mu_long, truth.mu_long).max(rel(self.mu_lat, truth.mu_lat))
    }
}

/// Friction of one kind of ground, for the full model (§1.4).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Surface {
    /// Name (`concrete`).
    pub name: String,
    /// Longitudinal friction μ_x, driven by the wheel slip `r θ̇ - v_x`.
    pub mu_long: f64,
    /// Lateral friction μ_y.
    pub mu_lat: f64,
    /// Rolling resistance coefficient (a torque `r μ_r N` against the wheel's spin).
    pub rolling: f64,
}

impl Surface {
    /// Its friction coefficients.
    pub fn friction(&self) -> Friction {
        Friction {
            mu_long: self.mu_long,
            mu_lat: self.mu_lat,
            rolling: self.rolling,
        }
    }
}

impl Validate for Surface {
    fn validate(&self) -> Result<(), Invalid> {
        non_negative(&format!("{}.mu_long", self.name), self.mu_long)?;
        non_negative(&format!("{}.mu_lat", self.name), self.mu_lat)?;
        non_negative(&format!("{}.rolling", self.name), self.rolling)
    }
}

/// A region of the floor.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Region {
    /// Axis-aligned rectangle `[x0, x1] × [y0, y1]` \[m\].
    Rect {
        /// Lower x.
        x0: f64,
        /// Lower y.
        y0: f64,
        /// Upper x.
        x1: f64,
        /// Upper y.
        y1: f64,
    },
    /// Disc of radius `r` around `(x, y)` \[m\].
    Disc {
        /// Centre x.
        x: f64,
        /// Centre y.
        y: f64,
        /// Radius.
        r: f64,
    },
}

impl Region {
    /// Whether `(x, y)` is inside.
    pub fn contains(&self, x: f64, y: f64) -> bool {
        match *self {
            Region::Rect { x0, y0, x1, y1 } => (x0..=x1).contains(&x) && (y0..=y1).contains(&y),
            Region::Disc { x: cx, y: cy, r } => (x - cx).powi(2) + (y - cy).powi(2) <= r * r,
        }
    }
}

/// A patch of another surface on the floor.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Patch {
    /// Name of a surface of the map.
    pub surface: String,
    /// Where.
    pub region: Region,
}

/// The floor: a default surface and patches (the last patch containing a point wins).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SurfaceMap {
    /// Surfaces by name.
    pub surfaces: Vec<Surface>,
    /// The surface everywhere outside the patches.
    pub default: String,
    /// Patches, later ones on top.
    #[serde(default)]
    pub patches: Vec<Patch>,
}

impl SurfaceMap {
    /// One surface everywhere.
    pub fn uniform(surface: Surface) -> SurfaceMap {
        SurfaceMap {
            default: surface.name.clone(),
            surfaces: vec![surface],
            patches: Vec::new(),
        }
    }

    /// Concrete everywhere (μ_x 0.8, μ_y 0.6, rolling 0.02).
    pub fn concrete() -> SurfaceMap {
        SurfaceMap::uniform(Surface {
            name: "concrete".into(),
            mu_long: 0.8,
            mu_lat: 0.6,
            rolling: 0.02,
        })
    }

    /// The index of the surface at `(x, y)`: the surface of the last patch containing
    /// the point, else the default. A name that is not among the surfaces (a map that
    /// did not pass [`Validate`]) falls back to the first surface; `None` only for a
    /// map without surfaces.
    pub fn index_at(&self, x: f64, y: f64) -> Option<usize> {
        let index = |name: &str| {
            self.surfaces
                .iter()
                .position(|s| s.name == name)
                .or_else(|| (!self.surfaces.is_empty()).then_some(0))
        };
        self.patches
            .iter()
            .rev()
            .find(|p| p.region.contains(x, y))
            .map_or_else(|| index(&self.default), |p| index(&p.surface))
    }

    /// The surface at `(x, y)` (`None` only for a map without surfaces, which
    /// [`Validate`] rejects).
    pub fn at(&self, x: f64, y: f64) -> Option<&Surface> {
        self.index_at(x, y).and_then(|i| self.surfaces.get(i))
    }
}

impl Validate for SurfaceMap {
    fn validate(&self) -> Result<(), Invalid> {
        if self.surfaces.is_empty() {
            return Err((
                "surfaces".into(),
                "[]".into(),
                "must list at least one surface",
            ));
        }
        for (i, s) in self.surfaces.iter().enumerate() {
            s.validate()?;
            if self.surfaces[..i].iter().any(|t| t.name == s.name) {
                return Err((
                    format!("surfaces[{i}].name"),
                    s.name.clone(),
                    "must differ from the names of the other surfaces",
                ));
            }
        }
        let known = |name: &str| self.surfaces.iter().any(|s| s.name == name);
        if !known(&self.default) {
            return Err((
                "default".into(),
                self.default.clone(),
                "must name one of the surfaces",
            ));
        }
        for (i, p) in self.patches.iter().enumerate() {
            if !known(&p.surface) {
                return Err((
                    format!("patches[{i}].surface"),
                    p.surface.clone(),
                    "must name one of the surfaces",
                ));
            }
            match p.region {
                Region::Rect { x0, y0, x1, y1 } => {
                    for (f, v) in [("x0", x0), ("y0", y0), ("x1", x1), ("y1", y1)] {
                        finite(&format!("patches[{i}].{f}"), v)?;
                    }
                    if x1 < x0 || y1 < y0 {
                        return Err((
                            format!("patches[{i}]"),
                            format!("{:?}", p.region),
                            "needs x0 <= x1 and y0 <= y1",
                        ));
                    }
                }
                Region::Disc { x, y, r } => {
                    finite(&format!("patches[{i}].x"), x)?;
                    finite(&format!("patches[{i}].y"), y)?;
                    positive(&format!("patches[{i}].r"), r)?;
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{ConfigError, parse};
    use std::path::Path;

    #[test]
    fn bad_values_are_rejected_with_the_field() {
        let mut p = PlatformParams::peer_default();
        p.mass = -40.0;
        assert_eq!(p.validate().unwrap_err().0, "mass");
        p.mass = f64::NAN;
        assert_eq!(p.validate().unwrap_err().0, "mass");
        let text = ron::to_string(&PlatformParams {
            wheel_inertia: 0.0,
            ..PlatformParams::peer_default()
        })
        .unwrap();
        let err = parse::<PlatformParams>(Path::new("p.ron"), &text).unwrap_err();
        assert!(
            matches!(err, ConfigError::Invalid { ref field, .. } if field == "wheel_inertia"),
            "{err}"
        );
        let err =
            parse::<PlatformParams>(Path::new("p.ron"), "(mass: 1.0, masss: 2.0)").unwrap_err();
        assert!(err.to_string().starts_with("p.ron:1:"), "{err}");
    }

    #[test]
    fn surfaces_by_position() {
        let mut map = SurfaceMap::concrete();
        map.surfaces.push(Surface {
            name: "ice".into(),
            mu_long: 0.1,
            mu_lat: 0.05,
            rolling: 0.01,
        });
        map.patches.push(Patch {
            surface: "ice".into(),
            region: Region::Disc {
                x: 1.0,
                y: 0.0,
                r: 0.5,
            },
        });
        assert_eq!(map.at(0.0, 0.0).unwrap().name, "concrete");
        assert_eq!(map.at(1.2, 0.1).unwrap().name, "ice");
        assert!(map.validate().is_ok());
        map.patches[0].surface = "lava".into();
        assert_eq!(map.validate().unwrap_err().0, "patches[0].surface");
    }

    #[test]
    fn empty_maps_and_duplicate_names_are_rejected_and_do_not_panic() {
        let empty = SurfaceMap {
            surfaces: Vec::new(),
            default: "concrete".into(),
            patches: Vec::new(),
        };
        assert_eq!(empty.validate().unwrap_err().0, "surfaces");
        assert_eq!(empty.index_at(0.0, 0.0), None);
        assert_eq!(empty.at(0.0, 0.0), None);

        let mut twice = SurfaceMap::concrete();
        twice.surfaces.push(Surface {
            name: "concrete".into(),
            mu_long: 0.1,
            mu_lat: 0.1,
            rolling: 0.0,
        });
        let (field, value, _) = twice.validate().unwrap_err();
        assert_eq!(
            (field.as_str(), value.as_str()),
            ("surfaces[1].name", "concrete")
        );
        // The same from a file: the error names the field.
        let text = ron::to_string(&twice).unwrap();
        let err = parse::<SurfaceMap>(Path::new("s.ron"), &text).unwrap_err();
        assert!(
            err.to_string().contains("surfaces[1].name = concrete"),
            "{err}"
        );
    }

    #[test]
    fn static_loads_sum_to_the_weight() {
        let p = PlatformParams {
            front: 0.15,
            rear: 0.25,
            ..PlatformParams::peer_default()
        };
        let n = p.static_loads();
        assert!((n.iter().sum::<f64>() - p.mass * p.gravity).abs() < 1e-9);
        assert!(
            n[0] > n[1],
            "the front carries more when the COM is nearer the front"
        );
    }
}
