//! Packing a per-tick stream into batches for a link to another host, and accounting for
//! sequence numbers on the far side: every sample that does not arrive is counted and placed
//! (which numbers are missing), never silently lost (docs/link.md).

use crate::msg::{SERVO_BATCH, ServoBatch, ServoSample};
use serde::{Deserialize, Serialize};

/// Gaps recorded one by one; beyond this only counted.
pub const MAX_GAPS: usize = 64;

/// A run of missing sequence numbers: `first..first + missing`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Gap {
    /// The first number missing.
    pub first: u64,
    /// How many are missing.
    pub missing: u64,
}

/// What a sequence-numbered stream delivered: counts of received, missing and repeated or
/// backward numbers, and the first [`MAX_GAPS`] gaps.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SeqGaps {
    /// Numbers received.
    pub received: u64,
    /// Numbers skipped (the sum of every gap).
    pub missing: u64,
    /// Gaps (runs of skipped numbers).
    pub gaps: u64,
    /// Numbers not above the last one (a repeat, or a restarted sender counting again).
    pub backwards: u64,
    /// The first gaps.
    pub first_gaps: Vec<Gap>,
    /// The first number received.
    pub first: Option<u64>,
    /// The last number received.
    pub last: Option<u64>,
}

impl SeqGaps {
    /// Takes the next number; returns the gap before it, if any. A number not above the last
    /// restarts the count from it (counted in `backwards`).
    pub fn push(&mut self, seq: u64) -> Option<Gap> {
        self.received += 1;
        self.first.get_or_insert(seq);
        let gap = match self.last {
            Some(last) if seq > last + 1 => Some(Gap {
                first: last + 1,
                missing: seq - last - 1,
            }),
            Some(last) if seq <= last => {
                self.backwards += 1;
                None
            }
            _ => None,
        };
        self.last = Some(seq);
        if let Some(g) = gap {
            self.gaps += 1;
            self.missing += g.missing;
            if self.first_gaps.len() < MAX_GAPS {
                self.first_gaps.push(g);
            }
        }
        gap
    }
}

/// Packs servo samples into [`ServoBatch`]es of [`SERVO_BATCH`], numbering the batches and
/// counting the samples it never saw (gaps in the servo's `seq`).
#[derive(Debug, Clone)]
pub struct Packer {
    batch: ServoBatch,
    seen: SeqGaps,
    missed: u64,
}

impl Packer {
    /// A packer whose batches carry `epoch` (its process's start time).
    pub fn new(epoch: u64) -> Self {
        Self {
            batch: ServoBatch {
                epoch,
                ..Default::default()
            },
            seen: SeqGaps::default(),
            missed: 0,
        }
    }

    /// The servo numbers it was given.
    pub fn seen(&self) -> &SeqGaps {
        &self.seen
    }

    /// Batches handed out.
    pub fn batches(&self) -> u64 {
        self.batch.seq
    }

    /// Adds a sample; hands a full batch to `emit`.
    pub fn push(&mut self, s: &ServoSample, emit: impl FnOnce(&ServoBatch)) {
        if let Some(g) = self.seen.push(s.seq) {
            self.missed += g.missing;
        }
        let n = self.batch.count as usize;
        self.batch.samples[n] = *s;
        self.batch.count += 1;
        if self.batch.count as usize == SERVO_BATCH {
            self.flush(emit);
        }
    }

    /// Hands the batch begun, if any, to `emit` (when the stream pauses).
    pub fn flush(&mut self, emit: impl FnOnce(&ServoBatch)) {
        if self.batch.count == 0 {
            return;
        }
        self.batch.seq += 1;
        self.batch.missed = std::mem::take(&mut self.missed);
        emit(&self.batch);
        self.batch.count = 0;
        self.batch.samples = [ServoSample::default(); SERVO_BATCH];
    }
}

/// The far side of a link: checks each batch's number and each sample's, and hands the samples
/// on in order.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Unpacker {
    /// The batch numbers (restarting with each packer incarnation).
    pub batches: SeqGaps,
    /// The servo's numbers.
    pub samples: SeqGaps,
    /// Samples the packer reported missing on its own host.
    pub missed_by_packer: u64,
    /// Packer incarnations seen.
    pub epochs: u64,
    /// Batches refused (wrong version, or a count out of range).
    pub refused: u64,
    #[serde(skip)]
    epoch: u64,
}

impl Unpacker {
    /// Takes a batch; hands each of its samples to `sample`. Returns false for a refused batch.
    pub fn push(&mut self, b: &ServoBatch, mut sample: impl FnMut(&ServoSample)) -> bool {
        if b.version != ServoBatch::VERSION || b.count == 0 || b.count as usize > SERVO_BATCH {
            self.refused += 1;
            return false;
        }
        if b.epoch != self.epoch {
            self.epoch = b.epoch;
            self.epochs += 1;
            // A new packer numbers its batches from 1 again: not a step back.
            self.batches.last = None;
        }
        self.batches.push(b.seq);
        self.missed_by_packer += b.missed;
        for s in b.used() {
            self.samples.push(s.seq);
            sample(s);
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(seq: u64) -> ServoSample {
        ServoSample {
            seq,
            ..Default::default()
        }
    }

    /// Gaps are placed and counted; a step back restarts the count.
    #[test]
    fn gaps_are_placed() {
        let mut g = SeqGaps::default();
        for s in [5, 6, 7, 10, 11, 15, 3, 4] {
            g.push(s);
        }
        assert_eq!(g.received, 8);
        assert_eq!(g.missing, 2 + 3);
        assert_eq!(g.gaps, 2);
        assert_eq!(g.backwards, 1);
        assert_eq!(
            g.first_gaps,
            vec![
                Gap {
                    first: 8,
                    missing: 2
                },
                Gap {
                    first: 12,
                    missing: 3
                }
            ]
        );
        assert_eq!((g.first, g.last), (Some(5), Some(4)));
    }

    /// Only the first MAX_GAPS gaps are kept, all are counted.
    #[test]
    fn gaps_beyond_the_list_are_counted() {
        let mut g = SeqGaps::default();
        for k in 0..(MAX_GAPS as u64 + 10) {
            g.push(2 * k);
        }
        assert_eq!(g.gaps, MAX_GAPS as u64 + 9);
        assert_eq!(g.missing, MAX_GAPS as u64 + 9);
        assert_eq!(g.first_gaps.len(), MAX_GAPS);
    }

    /// Packing then unpacking gives back every sample in order, with the batch numbers
    /// contiguous; a sample the packer never saw is reported by it and found by the far side.
    #[test]
    fn pack_and_unpack_round_trip() {
        let mut p = Packer::new(77);
        let mut batches = Vec::new();
        let n = 3 * SERVO_BATCH as u64 + 7;
        for k in 1..=n {
            if k == 60 {
                continue; // never seen by the packer
            }
            p.push(&sample(k), |b| batches.push(*b));
        }
        p.flush(|b| batches.push(*b));
        p.flush(|_| panic!("nothing left to flush"));
        assert_eq!(batches.len(), 4);
        assert_eq!(p.batches(), 4);
        assert_eq!(batches[3].count, 6);
        let mut u = Unpacker::default();
        let mut out = Vec::new();
        for b in &batches {
            assert!(u.push(b, |s| out.push(s.seq)));
        }
        let want: Vec<u64> = (1..=n).filter(|&k| k != 60).collect();
        assert_eq!(out, want);
        assert_eq!(u.batches.missing, 0);
        assert_eq!(u.batches.received, 4);
        assert_eq!(u.samples.missing, 1);
        assert_eq!(
            u.samples.first_gaps,
            vec![Gap {
                first: 60,
                missing: 1
            }]
        );
        assert_eq!(u.missed_by_packer, 1);
        assert_eq!(u.epochs, 1);
    }

    /// A lost batch shows as a gap in the batch numbers and in the servo's; a new packer
    /// (another epoch) numbering from 1 again is not a step back.
    #[test]
    fn lost_batches_and_new_packers_are_told_apart() {
        let mut batches = Vec::new();
        let mut p = Packer::new(1);
        for k in 1..=(3 * SERVO_BATCH as u64) {
            p.push(&sample(k), |b| batches.push(*b));
        }
        let mut q = Packer::new(2);
        for k in (3 * SERVO_BATCH as u64 + 1)..=(4 * SERVO_BATCH as u64) {
            q.push(&sample(k), |b| batches.push(*b));
        }
        batches.remove(1);
        let mut u = Unpacker::default();
        for b in &batches {
            u.push(b, |_| {});
        }
        assert_eq!(u.batches.gaps, 1);
        assert_eq!(u.batches.missing, 1);
        assert_eq!(u.batches.backwards, 0);
        assert_eq!(u.epochs, 2);
        assert_eq!(
            u.samples.first_gaps,
            vec![Gap {
                first: SERVO_BATCH as u64 + 1,
                missing: SERVO_BATCH as u64
            }]
        );
        let mut bad = batches[0];
        bad.count = SERVO_BATCH as u32 + 1;
        assert!(!u.push(&bad, |_| panic!("a refused batch hands nothing on")));
        bad.count = 0;
        assert!(!u.push(&bad, |_| {}));
        assert_eq!(u.refused, 2);
    }
}
