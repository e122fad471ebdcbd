//! The laser's noise source: xoshiro256++ (Blackman and Vigna), a small fast
//! generator with 256 bits of state that passes BigCrush, its state filled from the
//! device's noise seed by SplitMix64 as its authors recommend. It feeds `rand`'s
//! distributions (the ziggurat normal, uniform floats) like any generator.

use std::convert::Infallible;

use rand::TryRng;

/// One step of SplitMix64 on `state`.
pub fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// xoshiro256++.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Noise {
    s: [u64; 4],
}

impl Noise {
    /// The generator for a seed (any seed: SplitMix64 never fills the state with zeros).
    pub fn new(seed: u64) -> Noise {
        let mut sm = seed;
        Noise {
            s: [(); 4].map(|()| splitmix64(&mut sm)),
        }
    }

    fn next(&mut self) -> u64 {
        let s = &mut self.s;
        let out = (s[0].wrapping_add(s[3])).rotate_left(23).wrapping_add(s[0]);
        let t = s[1] << 17;
        s[2] ^= s[0];
        s[3] ^= s[1];
        s[1] ^= s[2];
        s[0] ^= s[3];
        s[2] ^= t;
        s[3] = s[3].rotate_left(45);
        out
    }
}

impl TryRng for Noise {
    type Error = Infallible;

    fn try_next_u32(&mut self) -> Result<u32, Infallible> {
        Ok((self.next() >> 32) as u32)
    }

    fn try_next_u64(&mut self) -> Result<u64, Infallible> {
        Ok(self.next())
    }

    fn try_fill_bytes(&mut self, dst: &mut [u8]) -> Result<(), Infallible> {
        for chunk in dst.chunks_mut(8) {
            let bytes = self.next().to_le_bytes();
            chunk.copy_from_slice(&bytes[..chunk.len()]);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_the_reference_sequence() {
        // The reference implementation (prng.di.unimi.it/xoshiro256plusplus.c) from
        // the state 1, 2, 3, 4.
        let mut n = Noise { s: [1, 2, 3, 4] };
        let first: Vec<u64> = (0..3).map(|_| n.next()).collect();
        assert_eq!(first, [41943041, 58720359, 3588806011781223]);
    }

    #[test]
    fn uniform_bits_are_balanced() {
        let mut n = Noise::new(7);
        let ones: u32 = (0..10_000).map(|_| n.next().count_ones()).sum();
        let p = f64::from(ones) / 640_000.0;
        assert!((p - 0.5).abs() < 0.005, "{p}");
        assert_ne!(Noise::new(1), Noise::new(2));
    }
}
