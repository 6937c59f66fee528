//! The camera renders objects where they are, in their colours.

mod common;

use common::{h1, room};
use nerve_devices::HeadCommand;
use nerve_sim::{CAMERA_FRAME_BYTES, CAMERA_HEIGHT, CAMERA_WIDTH, NoiseModel, SimError};

fn is_red(p: &[u8]) -> bool {
    p[0] > 100 && u16::from(p[0]) > 2 * u16::from(p[1]) && u16::from(p[0]) > 2 * u16::from(p[2])
}

/// Red pixels in the left and right halves of a frame.
fn red_halves(frame: &[u8]) -> (usize, usize) {
    let (mut l, mut r) = (0, 0);
    for row in 0..CAMERA_HEIGHT {
        for col in 0..CAMERA_WIDTH {
            let i = (row * CAMERA_WIDTH + col) * 3;
            if is_red(&frame[i..i + 3]) {
                if col < CAMERA_WIDTH / 2 { l += 1 } else { r += 1 }
            }
        }
    }
    (l, r)
}

const RED: &str = "[[object]]\nname = \"red\"\ncolor = [220, 30, 30]\nradius = 0.15\nz = [0.5, 1.1]\n\
                   position = [4.0, 2.2]\n";

#[test]
fn red_object_to_the_right_renders_in_the_right_half() {
    // robot at (2, 3) facing +x: the object at y = 2.2 is to its right
    let sim = h1(room(8.0, 2.0, 3.0, 0.0, RED), 1, NoiseModel::none());
    let mut frame = vec![0u8; CAMERA_FRAME_BYTES];
    sim.render_camera(&mut frame).expect("render");
    let (l, r) = red_halves(&frame);
    assert_eq!(l, 0, "no red on the left");
    assert!(r > 200, "red object visible on the right: {r} pixels");
    // walls, floor and ceiling fill the rest: no black pixels
    assert!(frame.chunks(3).all(|p| p != [0, 0, 0]));
}

#[test]
fn panning_the_head_moves_the_object_across_the_image() {
    let mut sim = h1(room(8.0, 2.0, 3.0, 0.0, RED), 1, NoiseModel::none());
    // pan right by 40°: the object (≈22° right) now appears left of centre
    sim.command_head(&HeadCommand { pan_cdeg: -4000, tilt_cdeg: 0 });
    common::run_for(&mut sim, 1.0);
    let mut frame = vec![0u8; CAMERA_FRAME_BYTES];
    sim.render_camera(&mut frame).expect("render");
    let (l, r) = red_halves(&frame);
    assert!(l > 200 && r == 0, "left {l}, right {r}");
}

#[test]
fn target_tube_is_upside_down() {
    // yellow over blue for a checkpoint, blue over yellow for the target
    let order = |target: bool| {
        let cp = format!("[[checkpoint]]\nid = 1\nposition = [3.5, 3.0]\ntarget = {target}\nradius = 0.1\n");
        let sim = h1(room(8.0, 2.0, 3.0, 0.0, &cp), 1, NoiseModel::none());
        let mut frame = vec![0u8; CAMERA_FRAME_BYTES];
        sim.render_camera(&mut frame).expect("render");
        let col = CAMERA_WIDTH / 2;
        let (mut first_yellow, mut first_blue) = (None, None);
        for row in 0..CAMERA_HEIGHT {
            let p = &frame[(row * CAMERA_WIDTH + col) * 3..][..3];
            if p[0] > 120 && p[1] > 100 && p[2] < 60 && first_yellow.is_none() {
                first_yellow = Some(row);
            }
            if p[2] > 120 && p[0] < 60 && first_blue.is_none() {
                first_blue = Some(row);
            }
        }
        (first_yellow.expect("yellow seen"), first_blue.expect("blue seen"))
    };
    let (y, b) = order(false);
    assert!(y < b, "checkpoint: yellow above blue ({y} vs {b})");
    let (y, b) = order(true);
    assert!(b < y, "target: blue above yellow ({b} vs {y})");
}

#[test]
fn wrong_buffer_size_is_an_error() {
    let sim = h1(room(8.0, 2.0, 3.0, 0.0, ""), 1, NoiseModel::none());
    let mut small = vec![0u8; 100];
    match sim.render_camera(&mut small) {
        Err(SimError::CameraBuffer { expected, got, .. }) => {
            assert_eq!((expected, got), (CAMERA_FRAME_BYTES, 100));
        }
        other => panic!("expected CameraBuffer, got {other:?}"),
    }
}
