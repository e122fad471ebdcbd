//! Signal packing: raw bits in an 8-byte payload, and raw <-> physical values.
//!
//! Table driven over [`SignalSpec`], so the generated typed messages, the CLI and a
//! DBC loaded at run time share one implementation.

use crate::CodecError;
use crate::spec::{ByteOrder, FRAME_LEN, MessageSpec, SignalSpec};

/// An 8-byte CAN payload.
pub type Payload = [u8; FRAME_LEN];

/// Copy a received data field into a payload, refusing any length but eight.
pub fn payload(message: &str, data: &[u8]) -> Result<Payload, CodecError> {
    Payload::try_from(data).map_err(|_| CodecError::WrongLength {
        message: message.to_owned(),
        len: data.len(),
    })
}

impl SignalSpec {
    /// Frame bit positions from the value's least significant bit upwards.
    fn lsb_first_bits(&self) -> Vec<usize> {
        let mut bits = self.bit_positions();
        if self.byte_order == ByteOrder::Motorola {
            bits.reverse();
        }
        bits
    }

    /// The raw value as the signal's integer type (sign-extended when signed).
    pub fn get_raw(&self, data: &Payload) -> i128 {
        let raw = match self.word_shift() {
            // The signal's bits are consecutive in the frame read as one integer
            // (little-endian for Intel, big-endian for Motorola's sawtooth order).
            Some(shift) => {
                let word = match self.byte_order {
                    ByteOrder::Intel => u64::from_le_bytes(*data),
                    ByteOrder::Motorola => u64::from_be_bytes(*data),
                };
                (word >> shift) & (u64::MAX >> (64 - u32::from(self.size)))
            }
            None => self.walk_raw(data),
        };
        let size = u32::from(self.size);
        if self.signed && raw >> (size - 1) & 1 == 1 {
            i128::from(raw) - (1i128 << size)
        } else {
            i128::from(raw)
        }
    }

    /// Where the signal's least significant bit is in the frame read as one integer
    /// (see [`SignalSpec::get_raw`]); `None` for a layout that runs outside the frame
    /// or has no bits.
    fn word_shift(&self) -> Option<u32> {
        let (start, size) = (u32::from(self.start_bit), u32::from(self.size));
        let shift = match self.byte_order {
            ByteOrder::Intel => Some(start),
            // The MSB's place counted from the frame's first bit sent, downwards.
            ByteOrder::Motorola => 64u32.checked_sub((start / 8) * 8 + (7 - start % 8) + size),
        };
        shift.filter(|s| size >= 1 && s + size <= 64)
    }

    /// The raw bits gathered one by one (least significant first).
    fn walk_raw(&self, data: &Payload) -> u64 {
        let mut raw: u64 = 0;
        for (i, bit) in self.lsb_first_bits().into_iter().enumerate() {
            if data[bit / 8] >> (bit % 8) & 1 == 1 {
                raw |= 1 << i;
            }
        }
        raw
    }

    /// The range of raw values the signal's bits can hold.
    pub fn raw_bounds(&self) -> (i128, i128) {
        let size = u32::from(self.size);
        if self.signed {
            (-(1i128 << (size - 1)), (1i128 << (size - 1)) - 1)
        } else {
            (0, (1i128 << size) - 1)
        }
    }

    /// Write a raw value; refuses one that does not fit the signal's bits.
    pub fn set_raw(&self, data: &mut Payload, raw: i128) -> Result<(), CodecError> {
        let (lo, hi) = self.raw_bounds();
        if raw < lo || raw > hi {
            return Err(CodecError::RawOutOfRange {
                signal: self.name.to_string(),
                raw,
                min: lo,
                max: hi,
            });
        }
        let bits_value = (raw & ((1i128 << self.size) - 1)) as u64;
        match self.word_shift() {
            // The bits are consecutive in the frame read as one integer: one mask.
            Some(shift) => {
                let mask = (u64::MAX >> (64 - u32::from(self.size))) << shift;
                let merge = |word: u64| (word & !mask) | (bits_value << shift & mask);
                *data = match self.byte_order {
                    ByteOrder::Intel => merge(u64::from_le_bytes(*data)).to_le_bytes(),
                    ByteOrder::Motorola => merge(u64::from_be_bytes(*data)).to_be_bytes(),
                };
            }
            None => self.walk_set(data, bits_value),
        }
        Ok(())
    }

    /// Write the raw bits one by one (least significant first).
    fn walk_set(&self, data: &mut Payload, bits_value: u64) {
        for (i, bit) in self.lsb_first_bits().into_iter().enumerate() {
            let mask = 1u8 << (bit % 8);
            if bits_value >> i & 1 == 1 {
                data[bit / 8] |= mask;
            } else {
                data[bit / 8] &= !mask;
            }
        }
    }

    /// Physical value of a raw value: raw * factor + offset.
    pub fn to_physical(&self, raw: i128) -> f64 {
        raw as f64 * self.factor + self.offset
    }

    /// The raw value nearest to a physical one (rounded, not truncated), refusing
    /// values outside the DBC's [min|max] range or the signal's bits.
    pub fn to_raw(&self, physical: f64) -> Result<i128, CodecError> {
        // Half a resolution step of slack: a value that rounds onto the limit is in range.
        let slack = self.factor.abs() / 2.0;
        if !physical.is_finite() || physical < self.min - slack || physical > self.max + slack {
            return Err(CodecError::OutOfRange {
                signal: self.name.to_string(),
                value: physical,
                min: self.min,
                max: self.max,
            });
        }
        let raw = ((physical - self.offset) / self.factor).round() as i128;
        let (lo, hi) = self.raw_bounds();
        if raw < lo || raw > hi {
            return Err(CodecError::RawOutOfRange {
                signal: self.name.to_string(),
                raw,
                min: lo,
                max: hi,
            });
        }
        Ok(raw)
    }

    /// Read the physical value.
    pub fn get(&self, data: &Payload) -> f64 {
        self.to_physical(self.get_raw(data))
    }

    /// Write a physical value (rounded to the nearest raw step).
    pub fn set(&self, data: &mut Payload, physical: f64) -> Result<(), CodecError> {
        let raw = self.to_raw(physical)?;
        self.set_raw(data, raw)
    }
}

/// One decoded signal, for display.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SignalValue<'a> {
    pub name: &'a str,
    pub raw: i128,
    pub value: f64,
    #[serde(skip_serializing_if = "str::is_empty")]
    pub unit: &'a str,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub label: Option<&'a str>,
}

impl MessageSpec {
    /// Decode every signal of a payload.
    pub fn decode_all<'a>(&'a self, data: &Payload) -> Vec<SignalValue<'a>> {
        self.signals
            .iter()
            .map(|s| {
                let raw = s.get_raw(data);
                SignalValue {
                    name: &s.name,
                    raw,
                    value: s.to_physical(raw),
                    unit: &s.unit,
                    label: i64::try_from(raw).ok().and_then(|r| s.label(r)),
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::borrow::Cow;

    fn signal(start_bit: u16, size: u8, byte_order: ByteOrder) -> SignalSpec {
        SignalSpec {
            name: Cow::Borrowed("s"),
            start_bit,
            size,
            byte_order,
            signed: false,
            factor: 1.0,
            offset: 0.0,
            min: 0.0,
            max: 0.0,
            unit: Cow::Borrowed(""),
            receivers: Cow::Borrowed(&[]),
            values: Cow::Borrowed(&[]),
            comment: Cow::Borrowed(""),
        }
    }

    /// The one-mask path writes and reads exactly the bits the walk over bit positions
    /// does, for every layout within the frame of both byte orders.
    #[test]
    fn word_path_agrees_with_the_bit_walk() {
        let mut seed = 0x1234_5678_9abc_def0u64;
        let mut next = || {
            seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
            seed
        };
        let mut layouts = 0;
        for order in [ByteOrder::Intel, ByteOrder::Motorola] {
            for start in 0..64u16 {
                for size in 1..=64u8 {
                    let s = signal(start, size, order);
                    if s.word_shift().is_none() || s.bit_positions().iter().any(|&b| b >= 64) {
                        continue;
                    }
                    layouts += 1;
                    let (data, value) = (next().to_le_bytes(), next() >> (64 - u32::from(size)));
                    let (mut fast, mut walked) = (data, data);
                    s.set_raw(&mut fast, i128::from(value)).expect("fits");
                    s.walk_set(&mut walked, value);
                    assert_eq!(fast, walked, "{order:?} {start}|{size}");
                    assert_eq!(s.get_raw(&fast), i128::from(s.walk_raw(&fast)));
                    assert_eq!(s.get_raw(&fast), i128::from(value));
                }
            }
        }
        assert!(layouts > 2000, "{layouts}");
    }
}
