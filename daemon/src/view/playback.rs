//! A dance file for the view's playback mode (`danced view`): the poses resampled to the view's
//! rate and encoded as the VMC bundles a live run sends, so the page applies both the same way.

use model::rig::{Pose, blend};
use protocols::{PacketPool, VmcEncoder};

use crate::frame::FrameBuilder;

/// Frames per second of the playback file (a display's rate; the poses are interpolated).
pub const PLAYBACK_RATE_HZ: f64 = 60.0;

/// `poses` at `fps`, resampled to [`PLAYBACK_RATE_HZ`] and encoded as VMC bundles, each after
/// its length (u32, little-endian); also how many frames that is.
pub fn dance_packets(poses: &[Pose], fps: f64) -> (Vec<u8>, usize) {
    let mut out = Vec::new();
    if poses.is_empty() || !(fps.is_finite() && fps > 0.0) {
        return (out, 0);
    }
    let duration = poses.len() as f64 / fps;
    let frames = (duration * PLAYBACK_RATE_HZ).floor().max(1.0) as usize;
    let mut builder = FrameBuilder::new();
    let mut vmc = VmcEncoder::new(false);
    let mut pool = PacketPool::new();
    let mut pose = Pose::rest();
    for i in 0..frames {
        let t = i as f64 / PLAYBACK_RATE_HZ;
        let x = t * fps;
        let a = (x.floor() as usize).min(poses.len() - 1);
        let b = (a + 1).min(poses.len() - 1);
        blend(&poses[a], &poses[b], (x - a as f64) as f32, &mut pose);
        vmc.write_frame(builder.build(i as u64, t, &pose, 0.0), &mut pool);
        for p in pool.packets() {
            out.extend_from_slice(&(p.len() as u32).to_le_bytes());
            out.extend_from_slice(p);
        }
    }
    (out, frames)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Quat;
    use model::rig::Joint;

    #[test]
    fn resamples_to_the_view_rate_and_interpolates() {
        let mut up = Pose::rest();
        up.set_rotation(Joint::LeftUpperArm, Quat::from_rotation_z(1.0));
        let poses = [Pose::rest(), up];
        let (bytes, frames) = dance_packets(&poses, 2.0);
        // 1 s of dance at 60 Hz.
        assert_eq!(frames, 60);
        let mut at = 0;
        let mut arm_angles = Vec::new();
        while at < bytes.len() {
            let n = u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
            let (_, packet) = rosc::decoder::decode_udp(&bytes[at + 4..at + 4 + n]).unwrap();
            let rosc::OscPacket::Bundle(b) = packet else {
                panic!("a bundle per frame")
            };
            for c in b.content {
                if let rosc::OscPacket::Message(m) = c
                    && m.args.first() == Some(&rosc::OscType::String("LeftUpperArm".into()))
                {
                    let qz = m.args[6].clone().float().unwrap();
                    arm_angles.push(2.0 * qz.asin().abs());
                }
            }
            at += 4 + n;
        }
        assert_eq!(arm_angles.len(), 60);
        // Frame 15 is a quarter second in: halfway from rest to the raised arm.
        assert!((arm_angles[15] - 0.5).abs() < 1e-3, "{}", arm_angles[15]);
        assert!(arm_angles[59] > 0.95);
        assert_eq!(dance_packets(&[], 25.0).1, 0);
    }
}
