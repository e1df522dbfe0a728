//! Joining the world and controller streams tick by tick, counting what was lost, repeated or
//! out of order.

use crate::msg::{PlantSample, ServoSample};
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;

/// What the joiner counted (the run report's `samples`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SampleCounts {
    /// World samples received (repeats dropped not counted).
    pub plant_received: u64,
    /// World samples a restarted servo sent again, identical, and dropped.
    pub plant_repeats_dropped: u64,
    /// Controller samples received.
    pub servo_received: u64,
    /// Ticks with both samples.
    pub paired: u64,
    /// World ticks missing.
    pub plant_lost: u64,
    /// Controller ticks missing.
    pub servo_lost: u64,
    /// Runs of missing world ticks.
    pub plant_gaps: u64,
    /// The longest run of missing world ticks.
    pub largest_gap_ticks: u64,
    /// Samples with an old sequence number and other contents.
    pub reordered: u64,
    /// Force samples received (injected ones included).
    pub wrench_received: u64,
}

/// Joins the plant and servo streams by tick and counts what was lost or out of order.
#[derive(Debug, Default)]
pub struct Joiner {
    plant: VecDeque<PlantSample>,
    servo: VecDeque<ServoSample>,
    last_servo: Option<u64>,
    /// The newest world sample in order (its `seq` is the last tick received); a restarted
    /// servo's first sample may repeat it.
    newest_plant: Option<PlantSample>,
    /// World samples a restarted servo sent again, identical, and dropped here.
    plant_repeats: u64,
    plant_received: u64,
    servo_received: u64,
    plant_gaps: u64,
    plant_lost: u64,
    servo_lost: u64,
    reordered: u64,
    paired: u64,
    max_gap_ticks: u64,
}

impl Joiner {
    /// What was counted, with the force samples counted elsewhere.
    pub fn counts(&self, wrench_received: u64) -> SampleCounts {
        SampleCounts {
            plant_received: self.plant_received,
            plant_repeats_dropped: self.plant_repeats,
            servo_received: self.servo_received,
            paired: self.paired,
            plant_lost: self.plant_lost,
            servo_lost: self.servo_lost,
            plant_gaps: self.plant_gaps,
            largest_gap_ticks: self.max_gap_ticks,
            reordered: self.reordered,
            wrench_received,
        }
    }

    /// True (and counted) if `p` equals the newest world sample in every field: a restarted
    /// servo's first sample repeats its predecessor's last tick, which may or may not have
    /// been delivered (servo_board.rs). Anything else with an old sequence number is
    /// `reordered`.
    pub fn is_repeat(&mut self, p: &PlantSample) -> bool {
        let repeat = self.newest_plant.as_ref() == Some(p);
        self.plant_repeats += u64::from(repeat);
        repeat
    }

    /// A world sample, in arrival order: counted, and queued for pairing unless its tick is
    /// not newer than the newest one (then it is counted as reordered and dropped).
    pub fn push_plant(&mut self, p: PlantSample) {
        self.plant_received += 1;
        if let Some(l) = self.newest_plant.map(|n| n.seq) {
            if p.seq <= l {
                self.reordered += 1;
                return;
            }
            if p.seq > l + 1 {
                self.plant_gaps += 1;
                self.plant_lost += p.seq - l - 1;
                self.max_gap_ticks = self.max_gap_ticks.max(p.seq - l - 1);
            }
        }
        self.newest_plant = Some(p);
        self.plant.push_back(p);
    }

    /// A controller sample, in arrival order: counted, and queued for pairing unless its tick
    /// is not newer than the last one.
    pub fn push_servo(&mut self, s: ServoSample) {
        self.servo_received += 1;
        if let Some(l) = self.last_servo {
            if s.seq <= l {
                self.reordered += 1;
                return;
            }
            if s.seq > l + 1 {
                self.servo_lost += s.seq - l - 1;
            }
        }
        self.last_servo = Some(s.seq);
        self.servo.push_back(s);
    }

    /// Calls `f` with every queued world and controller sample of the same tick, in tick
    /// order; samples whose partner cannot come any more are dropped.
    pub fn pairs(&mut self, mut f: impl FnMut(&PlantSample, &ServoSample)) {
        while let (Some(p), Some(s)) = (self.plant.front(), self.servo.front()) {
            if p.seq == s.seq {
                f(p, s);
                self.paired += 1;
                self.plant.pop_front();
                self.servo.pop_front();
            } else if p.seq < s.seq {
                self.plant.pop_front();
            } else {
                self.servo.pop_front();
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plant(seq: u64, x: f64) -> PlantSample {
        PlantSample {
            seq,
            time_s: x,
            ..Default::default()
        }
    }

    /// A restarted servo's repeat of the last tick is dropped whether or not the tick had
    /// arrived; a different sample with an old sequence number is still reordering.
    #[test]
    fn a_repeated_world_sample_is_dropped_and_a_different_one_is_not() {
        let mut j = Joiner::default();
        for p in [plant(0, 0.0), plant(1, 0.1)] {
            assert!(!j.is_repeat(&p));
            j.push_plant(p);
        }
        assert!(j.is_repeat(&plant(1, 0.1)));
        assert!(!j.is_repeat(&plant(1, 0.2)));
        j.push_plant(plant(1, 0.2));
        // The tick never arrived from the dead servo: its repeat is the next tick.
        assert!(!j.is_repeat(&plant(2, 0.3)));
        j.push_plant(plant(2, 0.3));
        assert_eq!(
            (j.plant_repeats, j.reordered, j.plant_lost, j.plant_received),
            (1, 1, 0, 4)
        );
    }
}
