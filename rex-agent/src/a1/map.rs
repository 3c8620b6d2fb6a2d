//! The map a1 knows: the room's walls and the obstacles in it, and how far the
//! platform's centre keeps from them. `c1` refuses plans and fragments that leave
//! the free space; `e11` stops the platform when it leaves it, or heads out of it
//! faster than it can brake.

use std::fmt;

/// An axis-aligned rectangle `[x0, x1] × [y0, y1]` \[m\].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rect {
    /// Lower x.
    pub x0: f64,
    /// Lower y.
    pub y0: f64,
    /// Upper x.
    pub x1: f64,
    /// Upper y.
    pub y1: f64,
}

impl Rect {
    /// Distance from `(x, y)` to the rectangle (0 inside).
    pub fn distance(&self, x: f64, y: f64) -> f64 {
        let dx = (self.x0 - x).max(x - self.x1).max(0.0);
        let dy = (self.y0 - y).max(y - self.y1).max(0.0);
        dx.hypot(dy)
    }
}

impl fmt::Display for Rect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "[{}, {}] x [{}, {}]", self.x0, self.x1, self.y0, self.y1)
    }
}

/// Why a point is not free space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Blocked {
    /// Closer to a wall than the clearance, or outside the room (or not finite).
    Walls,
    /// Closer than the clearance to obstacle `k` (0-based, in the world's order).
    Obstacle(usize),
}

/// The room, the obstacles and the clearance.
#[derive(Clone, Debug, PartialEq)]
pub struct Map {
    /// The room's walls.
    pub room: Rect,
    /// Obstacles standing in it.
    pub obstacles: Vec<Rect>,
    /// How far the platform's centre keeps from walls and obstacles \[m\]: its
    /// footprint's radius and a margin.
    pub clearance: f64,
}

impl Default for Map {
    /// A 12 m × 12 m room without obstacles, 0.5 m of clearance.
    fn default() -> Self {
        Map {
            room: Rect {
                x0: -6.0,
                y0: -6.0,
                x1: 6.0,
                y1: 6.0,
            },
            obstacles: Vec::new(),
            clearance: 0.5,
        }
    }
}

impl Map {
    /// Whether `(x, y)` is free space: inside the room and at least `clearance`
    /// from its walls and from every obstacle.
    pub fn check(&self, x: f64, y: f64) -> Result<(), Blocked> {
        let c = self.clearance;
        let r = &self.room;
        let inside = x - r.x0 >= c && r.x1 - x >= c && y - r.y0 >= c && r.y1 - y >= c;
        if !inside {
            // NaN lands here too: not free.
            return Err(Blocked::Walls);
        }
        match self.obstacles.iter().position(|o| o.distance(x, y) < c) {
            Some(k) => Err(Blocked::Obstacle(k)),
            None => Ok(()),
        }
    }

    /// `check` with a sentence for reports: "(4.30, 4.20) is within 0.50 m of
    /// obstacle 4 [4, 4.6] x [4, 4.6]".
    pub fn explain(&self, x: f64, y: f64) -> Result<(), String> {
        self.check(x, y).map_err(|b| match b {
            Blocked::Walls => format!(
                "({x:.2}, {y:.2}) is not {:.2} m inside the room {}",
                self.clearance, self.room
            ),
            Blocked::Obstacle(k) => format!(
                "({x:.2}, {y:.2}) is within {:.2} m of obstacle {} {}",
                self.clearance,
                k + 1,
                self.obstacles[k]
            ),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::camera::SceneConfig;

    #[test]
    fn free_space_keeps_the_clearance_from_walls_and_obstacles() {
        let map = Map::of_scene(&SceneConfig::default_room(), 0.5);
        assert_eq!(map.check(0.0, 0.0), Ok(()));
        assert_eq!(map.check(-5.49, 0.0), Ok(()));
        assert_eq!(map.check(-5.51, 0.0), Err(Blocked::Walls));
        // The crate at [4.8, 5.6] x [-0.8, 0.4].
        assert_eq!(map.check(4.35, 0.0), Err(Blocked::Obstacle(5)));
        assert_eq!(map.check(-7.45, 0.0), Err(Blocked::Walls));
        assert_eq!(map.check(f64::NAN, 0.0), Err(Blocked::Walls));
        // The pillar at [4, 4.6] x [4, 4.6]: its corner is 0.4 m from (3.72, 3.72).
        assert_eq!(map.check(3.72, 3.72), Err(Blocked::Obstacle(3)));
        assert_eq!(map.check(3.6, 3.6), Ok(()));
        let why = map.explain(4.3, 4.3).unwrap_err();
        assert!(why.contains("obstacle 4 [4, 4.6] x [4, 4.6]"), "{why}");
        let why = map.explain(-7.45, 0.0).unwrap_err();
        assert!(why.contains("not 0.50 m inside the room"), "{why}");
    }
}
