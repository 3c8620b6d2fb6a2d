//! Unit tests of the renderer: the pinhole round trip, culling obstacles to their
//! screen rectangles, the row-stepped image against a ray cast per pixel, the
//! blocked walls against the one-pixel path, disparity, invalid cameras and scenes,
//! texture everywhere.

use super::*;
use crate::world::camera::scene::Room;

fn renderer() -> Renderer {
    Renderer::new(CameraConfig::default(), SceneConfig::default_room()).unwrap()
}

#[test]
fn rays_round_trip_through_the_pinhole_model() {
    let r = renderer();
    let pose = r.camera.left_pose([0.3, -0.4, 0.7]);
    for (u, v) in [(10.5, 10.5), (320.5, 240.5), (600.5, 400.5), (100.5, 470.5)] {
        let hit = r
            .cast(&pose, u, v)
            .expect("every ray hits something in a closed room");
        let (pu, pv, _) = r.camera.project(&pose, hit.point).unwrap();
        assert!(
            (pu - u).abs() < 1e-3 && (pv - v).abs() < 1e-3,
            "({u}, {v}) -> {hit:?} -> ({pu}, {pv})"
        );
    }
    // Below the horizon, looking down: the floor.
    let hit = r.cast(&pose, 320.5, 470.5).unwrap();
    assert_eq!(hit.surface, Surface::Floor);
    assert!(hit.point[2].abs() < 1e-4);
}

#[test]
fn culling_obstacles_to_their_clipped_screen_rectangles_changes_no_pixel() {
    // Against every obstacle tested at every pixel: poses all over the room,
    // headings all round, some right against an obstacle (half of it behind the
    // camera) and some with every obstacle behind. `render` runs the AVX2 clone
    // where the machine has AVX2, `render_with` here the baseline code: the
    // comparison covers both.
    let r = renderer();
    let (w, h) = (r.camera.width as i64, r.camera.height as i64);
    let everywhere: Vec<(usize, Rect)> = (0..r.boxes.len())
        .map(|i| (i, (0, w - 1, 0, h - 1)))
        .collect();
    let n = (w * h) as usize;
    let (mut fast, mut slow) = (vec![0u8; n], vec![0u8; n]);
    let mut culled = 0;
    for body in [
        [0.0, 0.0, 0.0],
        [0.3, -0.4, 2.1],
        [-3.5, -3.5, -2.4],
        [-3.7, -3.7, 0.3],
        [3.5, 3.5, 0.8],
        [4.2, 0.0, 0.05],
        [4.4, -0.2, 3.0],
        [-0.2, 3.9, 1.57],
        [-0.2, 4.3, -1.2],
        [5.0, 5.0, -2.4],
    ] {
        for pose in [r.camera.left_pose(body), r.camera.right_pose(body)] {
            r.render(&pose, &mut fast);
            r.render_with(&pose, &everywhere, &mut slow);
            let differ = fast.iter().zip(&slow).filter(|(a, b)| a != b).count();
            assert_eq!(differ, 0, "{body:?}: {differ} pixels differ");
            culled += (0..r.boxes.len())
                .filter(|&i| r.screen_rect(&pose, i).is_none())
                .count();
        }
    }
    assert!(
        culled > 20,
        "most poses leave obstacles out of view: {culled}"
    );
}

#[test]
fn the_row_stepped_image_is_a_ray_cast_at_every_pixel() {
    // Each pixel against its own ray (`cast`, in f64 to the hit, shaded from the
    // world point): the row's floor interval, the fixed-point texel steps and
    // the wall and obstacle paths may differ from it by rounding only (a grey
    // level or two inside a surface, a pixel's width at its edges).
    let r = renderer();
    let (w, h) = (r.camera.width as usize, r.camera.height as usize);
    let mut image = vec![0u8; w * h];
    for body in [
        [0.0, 0.0, 0.0],
        [3.5, 3.5, 0.8],
        [-3.7, -3.7, 0.3],
        [4.4, -0.2, 3.0],
    ] {
        let pose = r.camera.left_pose(body);
        r.render(&pose, &mut image);
        let (mut close, mut total) = (0usize, 0usize);
        let mut floor = 0usize;
        for v in (0..h).step_by(3) {
            for u in (0..w).step_by(3) {
                let expected = match r.cast(&pose, u as f64, v as f64) {
                    Some(hit) => {
                        floor += usize::from(hit.surface == Surface::Floor);
                        r.shade(hit.point.map(|x| x as f32), hit.surface)
                    }
                    None => CEILING_LEVEL,
                };
                close += usize::from(image[v * w + u].abs_diff(expected) <= 2);
                total += 1;
            }
        }
        assert!(
            floor > total / 10,
            "{body:?}: the floor is in view ({floor} of {total})"
        );
        assert!(
            close as f64 >= 0.995 * total as f64,
            "{body:?}: {} of {total} pixels differ by more than 2 grey levels",
            total - close
        );
    }
}

#[test]
fn texel_fixed_is_the_saturating_conversion_over_its_range() {
    // Every f32 of [2²², 2²⁴), and the values around that range.
    for bits in 0x4a80_0000u32..0x4b80_0000 {
        let x = f32::from_bits(bits);
        assert_eq!(texel_fixed(x), (x as u32, true), "{x}");
    }
    for x in [
        f32::from_bits(0x4a80_0000 - 1),
        16_777_216.0,
        3e9,
        0.0,
        -1.0,
        -8_388_608.0,
        f32::NAN,
        f32::INFINITY,
    ] {
        assert!(!texel_fixed(x).1, "{x} is out of range");
    }
}

#[test]
fn the_blocked_walls_are_the_one_pixel_path_bit_for_bit() {
    // The rows of random camera poses in the shipped room and in a room of 1 km
    // (texel coordinates beyond `texel_fixed`'s range), with the row's floor or
    // ceiling distance as rendered and random ones (walls behind the plane).
    let mut rng = crate::math::rng::Rng::new(17);
    let big = SceneConfig {
        room: Room {
            x0: -500.0,
            y0: -40.0,
            x1: 500.0,
            y1: 300.0,
            height: 3.0,
        },
        obstacles: Vec::new(),
        texture_seed: 3,
    };
    // Pixels that see a wall, and pixels that see the floor or ceiling plane
    // (the one-pixel path's, in the blocked walls).
    let (mut on_walls, mut on_planes) = (0usize, 0usize);
    for r in [
        renderer(),
        Renderer::new(CameraConfig::default(), big).unwrap(),
    ] {
        let [x0, y0, x1, y1, _] = r.room;
        let (w, h) = (r.camera.width as usize, r.camera.height as usize);
        let (cu, cv) = r.camera.principal_point();
        let floor = &r.textures.floor;
        for _ in 0..40 {
            let mut at = |a: f32, b: f32| f64::from(a + (b - a) * rng.uniform() as f32);
            let body = [at(x0, x1), at(y0, y1), at(-3.2, 3.2)];
            let pose = r.camera.left_pose(body);
            let c = pose.center.map(|x| x as f32);
            let r0 = pose.to_world_dir([1.0, 0.0, 0.0]).map(|x| x as f32);
            for v in (0..h).step_by(7) {
                let d0 = pose
                    .to_world_dir([-cu, v as f64 - cv, r.camera.focal])
                    .map(|x| x as f32);
                let plane = if d0[2] < 0.0 {
                    (-c[2] / d0[2], Surface::Floor)
                } else {
                    ((r.room[4] - c[2]) / d0[2], Surface::Ceiling)
                };
                let row_floor = RowFloor {
                    u: (rng.uniform().to_bits() as i64, 1 << 20),
                    v: (rng.uniform().to_bits() as i64, -3 << 18),
                };
                let random = (20.0 * rng.uniform() as f32, plane.1);
                for row_plane in [plane, random, (f32::INFINITY, Surface::Floor)] {
                    let mut out = vec![0u8; w];
                    let from = (rng.uniform() * 100.0) as usize;
                    let rays = Rays { c, d0, r0 };
                    r.walls(&rays, row_plane, &row_floor, from, &mut out[from..]);
                    for k in from..w {
                        let d = axpy(k as f32, r0, d0);
                        let hit = r.wall(c, d, row_plane);
                        let expected = r.shade_hit(c, d, hit, floor, &row_floor, k);
                        assert_eq!(out[k], expected, "{body:?}, row {v}, column {k}");
                        if hit.1 == Surface::WallX || hit.1 == Surface::WallY {
                            on_walls += 1;
                        } else {
                            on_planes += 1;
                        }
                    }
                }
            }
        }
    }
    assert!(
        on_walls > 100_000 && on_planes > 100_000,
        "{on_walls} / {on_planes}"
    );
}

#[test]
fn disparity_of_a_wall_is_f_b_over_z() {
    // An empty room; the camera level, facing the wall x = 4 from x = 0: the wall
    // is at depth Z = 4 − 0.2 (mount) everywhere; match a patch between the images.
    let scene = SceneConfig {
        room: Room {
            x0: -4.0,
            y0: -6.0,
            x1: 4.0,
            y1: 6.0,
            height: 3.0,
        },
        obstacles: Vec::new(),
        texture_seed: 3,
    };
    let camera = CameraConfig {
        pitch: 0.0,
        ..CameraConfig::default()
    };
    let r = Renderer::new(camera.clone(), scene).unwrap();
    let (mut left, mut right) = (Vec::new(), Vec::new());
    r.render_pair([0.0, 0.0, 0.0], &mut left, &mut right);
    let z = 4.0 - camera.mount_forward;
    let expected = camera.focal * camera.baseline / z;
    let w = camera.width as usize;
    let (u0, v0, half) = (330usize, 200usize, 7usize);
    let sad = |d: usize| -> u64 {
        let mut s = 0u64;
        for y in v0 - half..=v0 + half {
            for x in u0 - half..=u0 + half {
                s += u64::from(left[y * w + x].abs_diff(right[y * w + x - d]));
            }
        }
        s
    };
    let best = (0..80).min_by_key(|&d| sad(d)).unwrap();
    assert!(
        (best as f64 - expected).abs() <= 1.0,
        "disparity {best} vs f b / Z = {expected}"
    );
    let row_shift = (0..3usize).min_by_key(|&dy| {
        let mut s = 0u64;
        for x in u0 - half..=u0 + half {
            s += u64::from(left[(v0 + dy) * w + x].abs_diff(right[v0 * w + x - best]));
        }
        s
    });
    assert_eq!(row_shift, Some(0), "rectified: matches lie on the same row");
}

#[test]
fn invalid_cameras_and_scenes_are_errors_not_panics() {
    let scene = SceneConfig::default_room;
    for (camera, field) in [
        (
            CameraConfig {
                width: 0,
                ..CameraConfig::default()
            },
            "width x height = 0x480",
        ),
        (
            CameraConfig {
                height: 100_000,
                ..CameraConfig::default()
            },
            "width x height = 640x100000",
        ),
        (
            CameraConfig {
                focal: 0.0,
                ..CameraConfig::default()
            },
            "focal = 0",
        ),
        (
            CameraConfig {
                focal: -400.0,
                ..CameraConfig::default()
            },
            "focal = -400",
        ),
        (
            CameraConfig {
                focal: f64::NAN,
                ..CameraConfig::default()
            },
            "focal = NaN",
        ),
        (
            CameraConfig {
                baseline: f64::INFINITY,
                ..CameraConfig::default()
            },
            "baseline = inf",
        ),
    ] {
        let err = Renderer::new(camera, scene()).unwrap_err().to_string();
        assert!(
            err.starts_with("<camera>: ") && err.contains(field),
            "{err}"
        );
    }
    let mut bad = scene();
    bad.room.x1 = f64::NAN;
    let err = Renderer::new(CameraConfig::default(), bad)
        .unwrap_err()
        .to_string();
    assert!(err.contains("<scene>: room.x1 = NaN"), "{err}");
}

#[test]
fn images_have_texture_everywhere_but_the_ceiling() {
    let r = renderer();
    let (mut left, mut right) = (Vec::new(), Vec::new());
    r.render_pair([0.0, 0.0, 0.3], &mut left, &mut right);
    let w = r.camera.width as usize;
    // Local contrast in the lower half (floor and walls).
    let mut textured_rows = 0;
    for y in (240..480).step_by(20) {
        let row = &left[y * w..(y + 1) * w];
        let mean = row.iter().map(|&x| f64::from(x)).sum::<f64>() / w as f64;
        let var = row
            .iter()
            .map(|&x| (f64::from(x) - mean).powi(2))
            .sum::<f64>()
            / w as f64;
        if var.sqrt() > 8.0 {
            textured_rows += 1;
        }
    }
    assert!(textured_rows >= 10, "textured rows: {textured_rows}");
    assert_ne!(left, right);
}
