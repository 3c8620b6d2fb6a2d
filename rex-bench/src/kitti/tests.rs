//! Unit tests of `kitti`: calib.txt read by KITTI tools, sequences written and read
//! back, damaged files, scripted paths and sequences (were rex-agent's
//! `world::camera::kitti` tests; its PNG and transform tests stay there).

use super::*;
use rex_agent::world::WorldConfig;
use rex_agent::world::camera::kitti::write_png;
use rex_agent::world::camera::{CameraConfig, Obstacle, Room, SceneConfig, SensorConfig};
use std::collections::HashMap;

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("rex-kitti-{name}-{}", std::process::id()));
    let _ = fs::remove_dir_all(&dir);
    dir
}

/// The `KEY: 12 numbers` lines of a calib.txt, as 3×4 matrices.
fn calib_matrices(path: &Path) -> HashMap<String, Pose34> {
    fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|line| {
            let (key, rest) = line.split_once(':').unwrap();
            let v: Vec<f64> = rest
                .split_whitespace()
                .map(|t| t.parse().unwrap())
                .collect();
            assert_eq!(v.len(), 12, "{line}");
            (
                key.to_owned(),
                [0, 1, 2].map(|i| [0, 1, 2, 3].map(|j| v[4 * i + j])),
            )
        })
        .collect()
}

fn apply(t: &Pose34, p: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| (0..3).map(|j| t[i][j] * p[j]).sum::<f64>() + t[i][3])
}

fn project(p: &Pose34, x: [f64; 3]) -> (f64, f64) {
    let h = [0, 1, 2].map(|i| (0..3).map(|j| p[i][j] * x[j]).sum::<f64>() + p[i][3]);
    (h[0] / h[2], h[1] / h[2])
}

#[test]
fn calib_txt_has_the_lines_kitti_tools_read() {
    let dir = temp_dir("lines");
    let camera = CameraConfig::default();
    SequenceWriter::create(&dir, &camera)
        .unwrap()
        .finish()
        .unwrap();
    let text = fs::read_to_string(dir.join("calib.txt")).unwrap();
    let keys: Vec<&str> = text.lines().filter_map(|l| l.split(':').next()).collect();
    assert_eq!(keys, ["P0", "P1", "P2", "P3", "Tr"]);
    let m = calib_matrices(&dir.join("calib.txt"));
    assert_eq!(m["P2"], m["P0"], "no colour camera: P2 repeats P0");
    assert_eq!(m["P3"], m["P1"], "and P3 repeats P1");
    assert_eq!(
        m["P0"],
        [
            [400.0, 0.0, 319.5, 0.0],
            [0.0, 400.0, 239.5, 0.0],
            [0.0, 0.0, 1.0, 0.0]
        ],
        "principal point ((w - 1)/2, (h - 1)/2)"
    );
    assert!((m["P1"][0][3] + 400.0 * 0.3).abs() < 1e-9);
    // Tr maps the body frame to the left camera: the camera centre (0.2 m ahead,
    // 0.5 m up) goes to the origin, the body's forward axis to the optical axis
    // pitched 0.1 rad down (+z forward, +y down).
    let tr = m["Tr"];
    let c = apply(&tr, [camera.mount_forward, 0.0, camera.mount_height]);
    assert!(c.iter().all(|x| x.abs() < 1e-12), "{c:?}");
    let ahead = apply(&tr, [camera.mount_forward + 1.0, 0.0, camera.mount_height]);
    assert!(
        (ahead[2] - 0.1f64.cos()).abs() < 1e-12 && (ahead[1] + 0.1f64.sin()).abs() < 1e-12,
        "forward is up in the image of a camera looking down: {ahead:?}"
    );
    let left = apply(&tr, [camera.mount_forward, 1.0, camera.mount_height]);
    assert!((left[0] + 1.0).abs() < 1e-12, "body y (left) is camera -x");
    let seq = Sequence::open(&dir).unwrap();
    assert_eq!(seq.body_to_camera, Some(tr));
    assert_eq!(seq.principal, (319.5, 239.5));

    // A calib.txt with P0 and P1 only (older sequences) still opens.
    let old: String = text.lines().take(2).map(|l| format!("{l}\n")).collect();
    fs::write(dir.join("calib.txt"), old).unwrap();
    let seq = Sequence::open(&dir).unwrap();
    assert_eq!(seq.body_to_camera, None);
    assert!((seq.baseline - 0.3).abs() < 1e-12);
    fs::write(dir.join("calib.txt"), format!("{text}Tr: 1 2 3\n")).unwrap();
    let err = Sequence::open(&dir).unwrap_err().to_string();
    assert!(err.contains("calib.txt") && err.contains("Tr"), "{err}");
    fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn mismatched_ground_truth_and_image_sizes_are_errors_naming_the_file() {
    let dir = temp_dir("mismatch");
    let camera = CameraConfig {
        width: 64,
        height: 48,
        ..CameraConfig::default()
    };
    let mut w = SequenceWriter::create(&dir, &camera).unwrap();
    let img = vec![7u8; 64 * 48];
    for k in 0..2 {
        w.push(
            k as f64 * 0.1,
            &camera.left_pose([0.1 * k as f64, 0.0, 0.0]),
            &img,
            &img,
        )
        .unwrap();
    }
    w.finish().unwrap();
    assert_eq!(Sequence::open(&dir).unwrap().len(), 2);
    // Two frames, one pose.
    let poses = fs::read_to_string(dir.join("poses.txt")).unwrap();
    let first: String = poses.lines().take(1).map(|l| format!("{l}\n")).collect();
    fs::write(dir.join("poses.txt"), first).unwrap();
    let err = Sequence::open(&dir).unwrap_err().to_string();
    assert!(
        err.contains("poses.txt") && err.contains("1 poses for 2 frames"),
        "{err}"
    );
    fs::write(dir.join("poses.txt"), poses).unwrap();
    // A right image of another size.
    write_png(
        &dir.join("image_1").join("000001.png"),
        32,
        48,
        &[0u8; 32 * 48],
    )
    .unwrap();
    let seq = Sequence::open(&dir).unwrap();
    let err = seq.frame(1).unwrap_err().to_string();
    assert!(
        err.contains("image_1/000001.png") && err.contains("32x48"),
        "{err}"
    );
    // A left image of another size: the left one is named, not the right.
    write_png(&dir.join("image_1").join("000001.png"), 64, 48, &img).unwrap();
    write_png(
        &dir.join("image_0").join("000001.png"),
        32,
        48,
        &[0u8; 32 * 48],
    )
    .unwrap();
    let err = seq.frame(1).unwrap_err().to_string();
    assert!(
        err.contains("image_0/000001.png")
            && err.contains("32x48, but the sequence's images are 64x48"),
        "{err}"
    );
    // Times that are not finite, or do not increase.
    for (times, want) in [
        ("0.0\nNaN\n", "frame 1: the time NaN is not a finite number"),
        ("0.0\ninf\n", "frame 1: the time inf is not a finite number"),
        (
            "0.5\n0.1\n",
            "frame 1: the time 0.1 does not come after frame 0's, 0.5",
        ),
    ] {
        fs::write(dir.join("times.txt"), times).unwrap();
        let err = Sequence::open(&dir).unwrap_err().to_string();
        assert!(err.contains("times.txt") && err.contains(want), "{err}");
    }
    fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_point_projected_with_calib_txt_is_on_that_pixel_of_the_rendered_images() {
    // A long room with a low ceiling, which renders as one flat grey level, and a
    // box in front of the camera. The top-left corner of the box's front face,
    // as the camera sees it, is a known 3D point: left of it and above it is the
    // ceiling, right of it and below it the textured box. Pixel centres are at
    // integer coordinates, so the pixels whose centres lie on the ceiling side
    // of the projected edges show the ceiling and the others show the box.
    let ceiling = 196u8; // the renderer's ceiling level
    let camera = CameraConfig {
        pitch: 0.0,
        ..CameraConfig::default()
    };
    let scene = SceneConfig {
        room: Room {
            x0: -2.0,
            y0: -10.0,
            x1: 40.0,
            y1: 10.0,
            height: 1.0,
        },
        obstacles: vec![Obstacle {
            x0: 3.0,
            y0: -1.0,
            x1: 4.0,
            y1: 0.48,
            height: 0.77,
        }],
        texture_seed: 5,
    };
    let corner = [3.0, 0.48, 0.77];
    let renderer = Renderer::new(camera.clone(), scene).unwrap();
    // Frames a little apart, so that the corner falls at various sub-pixel
    // positions.
    let bodies: Vec<[f64; 3]> = (0..12)
        .map(|k| [0.013 * k as f64, 0.0017 * k as f64, 0.0])
        .collect();
    let dir = temp_dir("pixel");
    let mut writer = SequenceWriter::create(&dir, &camera).unwrap();
    let (mut left, mut right) = (Vec::new(), Vec::new());
    for (k, body) in bodies.iter().enumerate() {
        renderer.render_pair(*body, &mut left, &mut right);
        writer
            .push(k as f64 * 0.1, &camera.left_pose(*body), &left, &right)
            .unwrap();
    }
    writer.finish().unwrap();

    // Everything from the files: the projection matrices, the poses, the images.
    let calib = calib_matrices(&dir.join("calib.txt"));
    let seq = Sequence::open(&dir).unwrap();
    let poses = seq.poses.clone().unwrap();
    // The corner in the first camera's frame (the frame of poses.txt).
    let in_first = camera.left_pose(bodies[0]).to_camera(corner);
    let w = camera.width as usize;
    // Counts of checked edges by which half of a pixel they fall in.
    let mut halves = [[0usize; 2]; 2];
    for (k, pose) in poses.iter().enumerate() {
        let (_, _, l, r) = seq.frame(k).unwrap();
        let x = apply(&invert(pose), in_first);
        for (p, image) in [(calib["P0"], &l), (calib["P1"], &r)] {
            let (u, v) = project(&p, x);
            let at = |i: usize, j: usize| image[j * w + i];
            let (iu, jv) = (u.ceil() as usize, v.ceil() as usize);
            // The vertical edge: pixel iu − 1 (centre < u) sees the ceiling,
            // pixel iu (centre > u) the box, on rows below the corner.
            let fu = u - u.floor();
            if (0.08..=0.92).contains(&fu) {
                halves[0][usize::from(fu > 0.5)] += 1;
                let rows = jv + 1..jv + 25;
                for j in rows.clone() {
                    assert_eq!(
                        at(iu - 1, j),
                        ceiling,
                        "frame {k}: u = {u:.3}, pixel ({}, {j}) is left of the edge",
                        iu - 1
                    );
                }
                let on_box = rows.clone().filter(|&j| at(iu, j) != ceiling).count();
                assert!(
                    on_box * 10 >= rows.len() * 9,
                    "frame {k}: u = {u:.3}, column {iu} should show the box"
                );
            }
            // The horizontal edge: row jv − 1 (centre < v) sees the ceiling, row
            // jv the box, in the columns right of the corner.
            let fv = v - v.floor();
            if (0.08..=0.92).contains(&fv) {
                halves[1][usize::from(fv > 0.5)] += 1;
                let columns = iu + 1..iu + 60;
                for i in columns.clone() {
                    assert_eq!(
                        at(i, jv - 1),
                        ceiling,
                        "frame {k}: v = {v:.3}, pixel ({i}, {}) is above the edge",
                        jv - 1
                    );
                }
                let on_box = columns.clone().filter(|&i| at(i, jv) != ceiling).count();
                assert!(
                    on_box * 10 >= columns.len() * 9,
                    "frame {k}: v = {v:.3}, row {jv} should show the box"
                );
            }
        }
    }
    // The edges fell on both halves of pixels, so a half-pixel error in either
    // direction would have shown.
    assert!(
        halves.iter().flatten().all(|&n| n >= 3),
        "sub-pixel positions checked (u: <½, >½; v: <½, >½): {halves:?}"
    );
    fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn tours_stay_in_the_room_move_forward_and_differ_by_seed() {
    let dt = 0.01;
    for seed in [1, 2, 11, 12, 99] {
        let path = ScriptedPath::Tour(seed);
        let mut last = path.pose(0.0);
        let (mut slowest, mut fastest, mut sharpest) = (f64::MAX, 0.0f64, 0.0f64);
        for k in 1..30_000 {
            let p = path.pose(k as f64 * dt);
            assert!(
                p[0].hypot(p[1]) < 4.05,
                "seed {seed}: {p:?} leaves the free room"
            );
            let (dx, dy) = (p[0] - last[0], p[1] - last[1]);
            let speed = dx.hypot(dy) / dt;
            // Forward: the heading is the direction of travel.
            let along = dx * p[2].cos() + dy * p[2].sin();
            assert!(along > 0.8 * speed * dt, "seed {seed}: not forward at {k}");
            let turn = (p[2] - last[2] + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                - std::f64::consts::PI;
            slowest = slowest.min(speed);
            fastest = fastest.max(speed);
            sharpest = sharpest.max(turn.abs() / dt);
            last = p;
        }
        assert!(
            slowest > 0.8 && fastest < 2.3,
            "seed {seed}: {slowest}..{fastest} m/s"
        );
        assert!(sharpest < 2.5, "seed {seed}: {sharpest} rad/s");
    }
    assert_eq!(
        ScriptedPath::Tour(3).pose(7.0),
        ScriptedPath::Tour(3).pose(7.0)
    );
    assert_ne!(
        ScriptedPath::Tour(3).pose(7.0),
        ScriptedPath::Tour(4).pose(7.0)
    );
    let frames = ScriptedPath::Tour(11).frames_for(200.0);
    assert!((1000..2500).contains(&frames), "{frames} frames for 200 m");
    assert_eq!("tour:12".parse(), Ok(ScriptedPath::Tour(12)));
    assert!("tour:x".parse::<ScriptedPath>().is_err());
}

#[test]
fn a_noisy_blurred_sequence_is_seeded_and_differs_from_the_ideal_one() {
    let scene = WorldConfig::shipped().unwrap().scene;
    let ideal = CameraConfig {
        width: 96,
        height: 64,
        focal: 60.0,
        ..CameraConfig::default()
    };
    let noisy = CameraConfig {
        sensor: SensorConfig::realistic(5),
        ..ideal.clone()
    };
    let write = |camera: &CameraConfig, name: &str| {
        let dir = temp_dir(name);
        let mut r = Renderer::new(camera.clone(), scene.clone()).unwrap();
        write_scripted(&dir, &mut r, ScriptedPath::Tour(2), 3).unwrap();
        let seq = Sequence::open(&dir).unwrap();
        let frames: Vec<_> = (0..3).map(|k| seq.frame(k).unwrap()).collect();
        let _ = fs::remove_dir_all(&dir);
        frames
    };
    let a = write(&noisy, "noisy-a");
    assert_eq!(
        a,
        write(&noisy, "noisy-b"),
        "the same seed, the same images"
    );
    let clean = write(&ideal, "ideal");
    for (n, c) in a.iter().zip(&clean) {
        assert_ne!(n.2, c.2);
        assert_ne!(n.3, c.3);
        // Noise and gains, not another picture: close on average.
        let mean_diff =
            n.2.iter()
                .zip(&c.2)
                .map(|(&x, &y)| (f64::from(x) - f64::from(y)).abs())
                .sum::<f64>()
                / n.2.len() as f64;
        assert!(mean_diff < 20.0, "{mean_diff}");
    }
}

#[test]
fn a_stored_sequence_is_current_only_for_the_renderer_camera_and_length_that_made_it() {
    let scene = WorldConfig::shipped().unwrap().scene;
    let camera = CameraConfig {
        width: 96,
        height: 64,
        focal: 60.0,
        sensor: SensorConfig::realistic(3),
        ..CameraConfig::default()
    };
    let dir = temp_dir("current");
    let mut r = Renderer::new(camera.clone(), scene.clone()).unwrap();
    write_scripted(&dir, &mut r, ScriptedPath::FigureEight, 4).unwrap();
    let seq = Sequence::open(&dir).unwrap();
    let path = ScriptedPath::FigureEight;
    assert!(is_current(&seq, &mut r, path, 4).unwrap());
    // Another length, path, texture (as another renderer would draw), camera or
    // sensor seed: not current.
    assert!(!is_current(&seq, &mut r, path, 5).unwrap());
    assert!(!is_current(&seq, &mut r, ScriptedPath::Tour(2), 4).unwrap());
    let other_scene = SceneConfig {
        texture_seed: scene.texture_seed + 1,
        ..scene.clone()
    };
    let mut textures = Renderer::new(camera.clone(), other_scene).unwrap();
    assert!(!is_current(&seq, &mut textures, path, 4).unwrap());
    let mut pitched = Renderer::new(
        CameraConfig {
            pitch: camera.pitch + 0.01,
            ..camera.clone()
        },
        scene.clone(),
    )
    .unwrap();
    assert!(!is_current(&seq, &mut pitched, path, 4).unwrap());
    let mut reseeded = Renderer::new(
        CameraConfig {
            sensor: SensorConfig::realistic(4),
            ..camera.clone()
        },
        scene,
    )
    .unwrap();
    assert!(!is_current(&seq, &mut reseeded, path, 4).unwrap());
    // A damaged image is an error naming it, not a panic.
    fs::write(dir.join("image_0").join("000003.png"), b"not a png").unwrap();
    let err = is_current(&seq, &mut r, path, 4).unwrap_err().to_string();
    assert!(err.contains("000003.png"), "{err}");
    let _ = fs::remove_dir_all(&dir);
}
