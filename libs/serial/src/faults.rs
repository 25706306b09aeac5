//! Faults an emulated device injects into what it sends.

use std::time::Duration;

use rand::Rng;

/// Faults for an emulator to inject, each a probability per frame sent
/// (`drop` per byte), plus a device that never answers and one unplugged
/// mid-run.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Faults {
    /// Random bytes before a frame (line noise).
    pub noise: f64,
    /// Each byte lost.
    pub drop: f64,
    /// One bit of the frame flipped (a bad checksum).
    pub corrupt: f64,
    /// The frame cut short.
    pub truncate: f64,
    /// Never answer anything.
    pub mute: bool,
    /// Unplug (close the line and remove its link) after this long.
    pub unplug_after: Option<Duration>,
    /// Plug back in this long after unplugging.
    pub replug_after: Option<Duration>,
}

/// What a [`Faults`] did so far.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Injected {
    /// Frames preceded by noise.
    pub noise: u64,
    /// Bytes dropped.
    pub dropped: u64,
    /// Frames with a flipped bit.
    pub corrupted: u64,
    /// Frames cut short.
    pub truncated: u64,
}

impl Faults {
    /// A device that never answers.
    pub fn mute() -> Faults {
        Faults {
            mute: true,
            ..Faults::default()
        }
    }

    /// A device unplugged `after` its line opens and plugged back in
    /// `back_after` later.
    pub fn unplug(after: Duration, back_after: Duration) -> Faults {
        Faults {
            unplug_after: Some(after),
            replug_after: Some(back_after),
            ..Faults::default()
        }
    }

    /// True when no byte is ever altered.
    pub fn clean(&self) -> bool {
        self.noise <= 0.0 && self.drop <= 0.0 && self.corrupt <= 0.0 && self.truncate <= 0.0
    }

    /// `frame` as the faulty line delivers it.
    pub fn apply(&self, frame: &[u8], rng: &mut impl Rng, n: &mut Injected) -> Vec<u8> {
        if self.clean() {
            return frame.to_vec();
        }
        let mut out = Vec::with_capacity(frame.len() + 8);
        if rng.gen_bool(self.noise.clamp(0.0, 1.0)) {
            n.noise += 1;
            let k = rng.gen_range(1..8);
            out.extend((0..k).map(|_| rng.gen::<u8>()));
        }
        let mut body = frame.to_vec();
        if !body.is_empty() && rng.gen_bool(self.corrupt.clamp(0.0, 1.0)) {
            n.corrupted += 1;
            let i = rng.gen_range(0..body.len());
            body[i] ^= 1 << rng.gen_range(0..8);
        }
        if body.len() > 1 && rng.gen_bool(self.truncate.clamp(0.0, 1.0)) {
            n.truncated += 1;
            let keep = rng.gen_range(1..body.len());
            body.truncate(keep);
        }
        let p = self.drop.clamp(0.0, 1.0);
        for b in body {
            if p > 0.0 && rng.gen_bool(p) {
                n.dropped += 1;
            } else {
                out.push(b);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn each_fault_alters_frames_and_is_counted() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let frame: Vec<u8> = (0..100).collect();
        let mut n = Injected::default();
        assert_eq!(Faults::default().apply(&frame, &mut rng, &mut n), frame);

        let f = Faults {
            corrupt: 1.0,
            ..Faults::default()
        };
        let out = f.apply(&frame, &mut rng, &mut n);
        assert_eq!(out.len(), 100);
        assert_eq!(out.iter().zip(&frame).filter(|(a, b)| a != b).count(), 1);

        let f = Faults {
            truncate: 1.0,
            ..Faults::default()
        };
        assert!(f.apply(&frame, &mut rng, &mut n).len() < 100);

        let f = Faults {
            noise: 1.0,
            ..Faults::default()
        };
        let out = f.apply(&frame, &mut rng, &mut n);
        assert!(out.len() > 100 && out.ends_with(&frame));

        let f = Faults {
            drop: 0.5,
            ..Faults::default()
        };
        let out = f.apply(&frame, &mut rng, &mut n);
        assert!(out.len() < 100);
        assert_eq!(
            n,
            Injected {
                noise: 1,
                dropped: 100 - out.len() as u64,
                corrupted: 1,
                truncated: 1
            }
        );
    }
}
