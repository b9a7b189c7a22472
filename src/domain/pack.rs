//! Byte packing of what ranks send each other: little-endian, floats as their raw bits, so a
//! value arrives bitwise as it left (docs/design.md §4 needs a ghost to be the owner's particle to
//! the last bit).

use nalgebra::{Quaternion, UnitQuaternion, Vector3};

/// Appends values to a byte buffer.
#[derive(Default)]
pub struct Writer {
    pub buf: Vec<u8>,
}

impl Writer {
    pub fn u64(&mut self, x: u64) {
        self.buf.extend_from_slice(&x.to_le_bytes());
    }
    pub fn u32(&mut self, x: u32) {
        self.buf.extend_from_slice(&x.to_le_bytes());
    }
    pub fn f64(&mut self, x: f64) {
        self.u64(x.to_bits());
    }
    pub fn v3(&mut self, v: &Vector3<f64>) {
        for k in 0..3 {
            self.f64(v[k]);
        }
    }
    /// A unit quaternion in nalgebra's storage order (i, j, k, w), not renormalised.
    pub fn quat(&mut self, q: &UnitQuaternion<f64>) {
        for c in q.as_ref().coords.iter() {
            self.f64(*c);
        }
    }
    pub fn bytes(&mut self, b: &[u8]) {
        self.u64(b.len() as u64);
        self.buf.extend_from_slice(b);
    }
}

/// Reads values back in the order they were written. A short buffer is a bug in the sender
/// (both sides run the same build), so it panics with what was being read.
pub struct Reader<'a> {
    buf: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    pub fn new(buf: &'a [u8]) -> Self {
        Reader { buf, at: 0 }
    }
    pub fn done(&self) -> bool {
        self.at >= self.buf.len()
    }
    fn take(&mut self, n: usize) -> &'a [u8] {
        let s = self
            .buf
            .get(self.at..self.at + n)
            .unwrap_or_else(|| panic!("rank message truncated at byte {}", self.at));
        self.at += n;
        s
    }
    pub fn u64(&mut self) -> u64 {
        u64::from_le_bytes(self.take(8).try_into().expect("8 bytes"))
    }
    pub fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.take(4).try_into().expect("4 bytes"))
    }
    pub fn f64(&mut self) -> f64 {
        f64::from_bits(self.u64())
    }
    pub fn v3(&mut self) -> Vector3<f64> {
        Vector3::new(self.f64(), self.f64(), self.f64())
    }
    pub fn quat(&mut self) -> UnitQuaternion<f64> {
        let (i, j, k, w) = (self.f64(), self.f64(), self.f64(), self.f64());
        UnitQuaternion::new_unchecked(Quaternion::new(w, i, j, k))
    }
    pub fn bytes(&mut self) -> &'a [u8] {
        let n = self.u64() as usize;
        self.take(n)
    }
}

/// `x` as bytes (one pass into a buffer of the final size: the GPU halo stages megabytes
/// through it each step).
pub fn f64s(x: &[f64]) -> Vec<u8> {
    let mut out = vec![0u8; 8 * x.len()];
    for (c, v) in out.chunks_exact_mut(8).zip(x) {
        c.copy_from_slice(&v.to_bits().to_le_bytes());
    }
    out
}

/// The floats of [`f64s`].
pub fn read_f64s(b: &[u8]) -> impl Iterator<Item = f64> + '_ {
    b.chunks_exact(8)
        .map(|c| f64::from_bits(u64::from_le_bytes(c.try_into().expect("8 bytes"))))
}

/// `x` as bytes.
pub fn u64s(x: &[u64]) -> Vec<u8> {
    let mut w = Writer::default();
    x.iter().for_each(|&v| w.u64(v));
    w.buf
}

/// The counters of [`u64s`].
pub fn read_u64s(b: &[u8]) -> impl Iterator<Item = u64> + '_ {
    b.chunks_exact(8)
        .map(|c| u64::from_le_bytes(c.try_into().expect("8 bytes")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_round_trip_bitwise() {
        let q = UnitQuaternion::from_euler_angles(0.3, -1.2, 2.9);
        let v = Vector3::new(-0.0, 1e-310, f64::MAX);
        let mut w = Writer::default();
        w.u64(u64::MAX - 3);
        w.u32(7);
        w.v3(&v);
        w.quat(&q);
        w.bytes(b"abc");
        let mut r = Reader::new(&w.buf);
        assert_eq!(r.u64(), u64::MAX - 3);
        assert_eq!(r.u32(), 7);
        let v2 = r.v3();
        assert!((0..3).all(|k| v2[k].to_bits() == v[k].to_bits()));
        let q2 = r.quat();
        assert!(
            q2.as_ref()
                .coords
                .iter()
                .zip(q.as_ref().coords.iter())
                .all(|(a, b)| a.to_bits() == b.to_bits())
        );
        assert_eq!(r.bytes(), b"abc");
        assert!(r.done());
    }
}
