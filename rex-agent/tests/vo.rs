//! Stereo visual odometry on pairs rendered by the simulated camera: what it
//! recovers, and the pairs it refuses (the algorithm is tested here, with the
//! simulated world as its fixture, so that `algorithms::vo` itself knows nothing
//! of the world).

use rex_agent::algorithms::vo::{Calibration, NoEstimate, StereoOdometry, VoSettings};
use rex_agent::world::camera::{CameraConfig, Renderer, SceneConfig};

fn camera() -> CameraConfig {
    CameraConfig::default()
}

#[test]
fn blank_saturated_and_tiny_pairs_give_no_estimate() {
    let c = camera();
    let (w, h) = (c.width as usize, c.height as usize);
    let mut vo = StereoOdometry::new(c.calibration(), VoSettings::default()).unwrap();
    for level in [0u8, 255, 128] {
        let img = vec![level; w * h];
        let r = vo.process(&img, &img, w, h);
        assert!(
            matches!(r, Err(NoEstimate::Textureless { .. })),
            "{level}: {r:?}"
        );
    }
    assert!(matches!(
        vo.process(&[0; 10], &[0; 10], 5, 2),
        Err(NoEstimate::BadImages(_))
    ));
    assert!(matches!(
        vo.process(&[0; 100], &[0; 99], 10, 10),
        Err(NoEstimate::BadImages(_))
    ));
    assert_eq!(vo.stats().motions, 0);
    assert!(
        StereoOdometry::new(
            Calibration {
                f: 0.0,
                ..c.calibration()
            },
            VoSettings::default()
        )
        .is_err()
    );
}

#[test]
fn a_swapped_pair_is_said_to_be_swapped() {
    // Before: the right image taken for the left gave motions, 77 % off, without
    // a word.
    let c = camera();
    let renderer = Renderer::new(c.clone(), SceneConfig::default_room()).unwrap();
    let (w, h) = (c.width as usize, c.height as usize);
    let mut vo = StereoOdometry::new(c.calibration(), VoSettings::default()).unwrap();
    let (mut l, mut r) = (Vec::new(), Vec::new());
    renderer.render_pair([0.0, 0.3, 0.2], &mut l, &mut r);
    let e = vo.process(&r, &l, w, h).unwrap_err();
    assert!(matches!(e, NoEstimate::SwappedStereo { .. }), "{e}");
    assert!(
        e.to_string()
            .contains("are the left and right images swapped?")
    );
    // The right way round, the same pair is fine.
    assert_eq!(vo.process(&l, &r, w, h), Ok(None));
}

#[test]
fn a_rendered_motion_is_recovered_and_a_blank_pair_is_bridged() {
    // Two pairs from the simulated camera, 10 cm forward and 2° of turn apart.
    let c = camera();
    let renderer = Renderer::new(c.clone(), SceneConfig::default_room()).unwrap();
    let (w, h) = (c.width as usize, c.height as usize);
    let mut vo = StereoOdometry::new(c.calibration(), VoSettings::default()).unwrap();
    let pose = |x: f64, phi: f64| [x, 0.3, phi];
    let pair = |p: [f64; 3]| {
        let (mut l, mut r) = (Vec::new(), Vec::new());
        renderer.render_pair(p, &mut l, &mut r);
        (l, r)
    };
    let (l0, r0) = pair(pose(0.0, 0.2));
    assert_eq!(vo.process(&l0, &r0, w, h), Ok(None));
    let (l1, r1) = pair(pose(0.1, 0.2 + 2f64.to_radians()));
    let m = vo.process(&l1, &r1, w, h).unwrap().unwrap();
    // Camera frame: z forward, x right, y down; the platform turned left
    // (counter-clockwise seen from above) and moved 10 cm forward.
    let tz = m.tr[2][3];
    assert!(
        (tz + 0.1).abs() < 0.01,
        "forward motion {tz} (points come 10 cm closer)"
    );
    let yaw = m.tr[0][2].atan2(m.tr[0][0]);
    assert!((yaw.abs() - 2f64.to_radians()).abs() < 0.002, "yaw {yaw}");
    assert!(m.inliers >= 30, "{m:?}");
    // A blank pair: no estimate; the next good pair has nothing to match
    // against; the one after recovers.
    let blank = vec![0u8; w * h];
    assert!(vo.process(&blank, &blank, w, h).is_err());
    let (l2, r2) = pair(pose(0.2, 0.2 + 4f64.to_radians()));
    assert_eq!(vo.process(&l2, &r2, w, h), Err(NoEstimate::NoReference));
    let (l3, r3) = pair(pose(0.3, 0.2 + 6f64.to_radians()));
    let m = vo.process(&l3, &r3, w, h).unwrap().unwrap();
    assert!((m.tr[2][3] + 0.1).abs() < 0.01);
}

#[test]
fn with_the_constant_velocity_prior_a_forward_drive_is_recovered() {
    // Four pairs 10 cm apart along a gentle turn: from the third pair on, the
    // previous motion predicts where the points move (libviso2's prior).
    let c = camera();
    let renderer = Renderer::new(c.clone(), SceneConfig::default_room()).unwrap();
    let (w, h) = (c.width as usize, c.height as usize);
    let settings = VoSettings {
        motion_prior_weight: 4.0,
        ..VoSettings::default()
    };
    let mut vo = StereoOdometry::new(c.calibration(), settings).unwrap();
    for k in 0..4 {
        let k = f64::from(k);
        let (mut l, mut r) = (Vec::new(), Vec::new());
        renderer.render_pair([0.1 * k, 0.3, 0.2 + 1f64.to_radians() * k], &mut l, &mut r);
        let Some(m) = vo.process(&l, &r, w, h).unwrap() else {
            assert_eq!(k, 0.0, "only the first pair has no motion");
            continue;
        };
        assert!((m.tr[2][3] + 0.1).abs() < 0.01, "pair {k}: {m:?}");
        let yaw = m.tr[0][2].atan2(m.tr[0][0]);
        assert!(
            (yaw.abs() - 1f64.to_radians()).abs() < 0.002,
            "pair {k}: yaw {yaw}"
        );
    }
    assert_eq!(vo.stats().motions, 3);
    for weight in [-1.0, f32::NAN, f32::INFINITY] {
        let settings = VoSettings {
            motion_prior_weight: weight,
            ..VoSettings::default()
        };
        assert!(StereoOdometry::new(c.calibration(), settings).is_err());
    }
}

#[test]
fn with_the_outlier_filter_a_forward_drive_is_recovered_from_fewer_matches() {
    // libviso2's Delaunay filter drops matches whose neighbours move otherwise
    // (in a room: at the edges of obstacles and walls); the motion stays.
    let c = camera();
    let renderer = Renderer::new(c.clone(), SceneConfig::default_room()).unwrap();
    let (w, h) = (c.width as usize, c.height as usize);
    let run = |outlier_filter: bool| {
        let settings = VoSettings {
            outlier_filter,
            ..VoSettings::default()
        };
        let mut vo = StereoOdometry::new(c.calibration(), settings).unwrap();
        let mut matches = 0;
        for k in 0..3 {
            let k = f64::from(k);
            let (mut l, mut r) = (Vec::new(), Vec::new());
            renderer.render_pair([0.1 * k, 0.3, 0.2 + 1f64.to_radians() * k], &mut l, &mut r);
            let Some(m) = vo.process(&l, &r, w, h).unwrap() else {
                continue;
            };
            assert!((m.tr[2][3] + 0.1).abs() < 0.01, "pair {k}: {m:?}");
            let yaw = m.tr[0][2].atan2(m.tr[0][0]);
            assert!((yaw.abs() - 1f64.to_radians()).abs() < 0.002, "yaw {yaw}");
            matches += m.matches;
        }
        assert_eq!(vo.stats().motions, 2);
        matches
    };
    let (without, with) = (run(false), run(true));
    assert!(
        with < without,
        "{with} matches with the filter, {without} without"
    );
}
