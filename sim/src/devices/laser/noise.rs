//! The laser's noise source. Each beam of each scan draws from a stream of its own:
//! SplitMix64 (Steele, Lea and Flood 2014; it passes BigCrush) started from a hash of
//! the device's noise seed, the scan's sequence number and the beam's index. A beam's
//! noise is therefore fixed by those three, whatever the other beams hit, and a beam
//! that returns nothing draws nothing (in the open most of a scan). The stream feeds
//! `rand`'s distributions (the ziggurat normal, uniform floats) like any generator.

use std::convert::Infallible;

use firmware_bridge::laser::MAX_BEAMS;
use rand::TryRng;

/// The increment of SplitMix64's state (the golden ratio's fraction, 2^64 / phi).
const GAMMA: u64 = 0x9E37_79B9_7F4A_7C15;

/// SplitMix64's output function (Stafford's Mix13): a bijection of 64-bit words that
/// flips each output bit with probability one half for any input bit flipped.
fn mix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// One step of SplitMix64 on `state`.
pub fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(GAMMA);
    mix(*state)
}

/// Bits of the counter that hold the beam's index (every beam of a frame fits).
const BEAM_BITS: u32 = 16;
const _: () = assert!(MAX_BEAMS < 1 << BEAM_BITS);

/// The noise of beam `beam` of scan `sequence`: a SplitMix64 stream.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BeamNoise {
    state: u64,
}

impl BeamNoise {
    /// The stream of a device with noise seed `seed`. The scan and the beam make one
    /// counter (distinct for every beam of the first 2^48 scans: 178,000 years at
    /// 50 Hz), mixed and combined with the seed, so distinct beams start from distinct
    /// states and neighbouring beams from unrelated ones.
    pub fn new(seed: u64, sequence: u64, beam: usize) -> BeamNoise {
        let counter = (sequence << BEAM_BITS) | beam as u64;
        BeamNoise {
            state: seed ^ mix(counter),
        }
    }
}

impl TryRng for BeamNoise {
    type Error = Infallible;

    fn try_next_u32(&mut self) -> Result<u32, Infallible> {
        Ok((splitmix64(&mut self.state) >> 32) as u32)
    }

    fn try_next_u64(&mut self) -> Result<u64, Infallible> {
        Ok(splitmix64(&mut self.state))
    }

    fn try_fill_bytes(&mut self, dst: &mut [u8]) -> Result<(), Infallible> {
        for chunk in dst.chunks_mut(8) {
            let bytes = splitmix64(&mut self.state).to_le_bytes();
            chunk.copy_from_slice(&bytes[..chunk.len()]);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use rand::Rng;

    use super::*;

    #[test]
    fn splitmix64_matches_the_reference_sequence() {
        // The reference implementation (prng.di.unimi.it/splitmix64.c) from state 0.
        let mut state = 0;
        let first: Vec<u64> = (0..3).map(|_| splitmix64(&mut state)).collect();
        assert_eq!(
            first,
            [
                0xE220_A839_7B1D_CDAF,
                0x6E78_9E6A_A1B9_65F4,
                0x06C4_5D18_8009_454F
            ]
        );
    }

    #[test]
    fn every_beam_of_a_scan_and_every_scan_has_a_stream_of_its_own() {
        let first = |seq, beam| BeamNoise::new(7, seq, beam).next_u64();
        let mut seen: Vec<u64> = (0..4)
            .flat_map(|seq| (0..MAX_BEAMS).map(move |beam| (seq, beam)))
            .map(|(seq, beam)| first(seq, beam))
            .collect();
        let n = seen.len();
        seen.sort_unstable();
        seen.dedup();
        assert_eq!(seen.len(), n, "two beams started alike");
        assert_eq!(first(3, 5), first(3, 5));
        assert_ne!(
            BeamNoise::new(1, 3, 5).next_u64(),
            BeamNoise::new(2, 3, 5).next_u64()
        );
    }

    #[test]
    fn uniform_bits_are_balanced_across_beams() {
        // The first word of each beam's stream, as a scan uses them.
        let ones: u32 = (0..10_000)
            .map(|k| {
                BeamNoise::new(7, k / 541, (k % 541) as usize)
                    .next_u64()
                    .count_ones()
            })
            .sum();
        let p = f64::from(ones) / 640_000.0;
        assert!((p - 0.5).abs() < 0.005, "{p}");
    }
}
