//! The subset of tev's TCP protocol (the image viewer tev, <https://github.com/Tom94/tev>; the
//! packets are read by `IpcPacket::interpretAs*` in its `src/Ipc.cpp`) that a live preview
//! needs: create an image, then update rectangles of it.
//!
//! Every packet is its length in bytes (`u32`, little-endian, counting these 4 bytes), then its
//! type (one byte), then its fields: `bool` as one byte, integers little-endian, strings as
//! their UTF-8 bytes and a terminating NUL. The types used here:
//!
//! - [`CREATE_IMAGE`] (4): grab focus (`bool`), image name, width and height (`i32`), channel
//!   count (`i32`), the channel names.
//! - [`UPDATE_IMAGE_V3`] (6): grab focus, image name, channel count (`i32`), the channel names,
//!   `x`, `y`, width, height of the rectangle (`i32`), each channel's offset (`i64`), then each
//!   channel's stride (`i64`), in floats, into the data that follows: `f32` values, channel `c`
//!   of the rectangle's pixel `i` (row by row) at `offset[c] + i * stride[c]`.

/// tev's port when it is started without `--hostname`.
pub const DEFAULT_PORT: u16 = 14158;
/// The packet type of `CreateImage`.
pub const CREATE_IMAGE: u8 = 4;
/// The packet type of `UpdateImageV3` (channels at an offset and stride).
pub const UPDATE_IMAGE_V3: u8 = 6;

/// The channels a preview sends: linear RGB.
pub const CHANNELS: [&str; 3] = ["R", "G", "B"];

/// A packet under construction: its bytes, the length still a placeholder.
struct Packet(Vec<u8>);

impl Packet {
    fn new(kind: u8) -> Packet {
        let mut bytes = vec![0; 4];
        bytes.push(kind);
        Packet(bytes)
    }

    fn bool(&mut self, b: bool) {
        self.0.push(u8::from(b));
    }

    fn i32(&mut self, v: i32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }

    fn i64(&mut self, v: i64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }

    /// A string without NUL bytes (one would end it early in tev), NUL-terminated.
    fn str(&mut self, s: &str) {
        self.0.extend(s.bytes().filter(|&b| b != 0));
        self.0.push(0);
    }

    /// The finished packet, its length filled in.
    fn finish(mut self) -> Vec<u8> {
        let len = u32::try_from(self.0.len()).expect("a tev packet under 4 GiB");
        self.0[..4].copy_from_slice(&len.to_le_bytes());
        self.0
    }
}

/// `CreateImage`: an empty `width x height` image named `name` with the channels [`CHANNELS`],
/// shown at once (it replaces an image of the same name).
pub fn create_image(name: &str, width: u32, height: u32) -> Vec<u8> {
    let mut p = Packet::new(CREATE_IMAGE);
    p.bool(true);
    p.str(name);
    p.i32(width as i32);
    p.i32(height as i32);
    p.i32(CHANNELS.len() as i32);
    for c in CHANNELS {
        p.str(c);
    }
    p.finish()
}

/// `UpdateImageV3`: the rectangle at `(x, y)`, `width x height`, of image `name` gets the RGB
/// pixels `rgb` (row by row, each pixel its three channels in turn).
pub fn update_image(name: &str, [x, y, width, height]: [u32; 4], rgb: &[[f32; 3]]) -> Vec<u8> {
    assert_eq!(rgb.len(), width as usize * height as usize);
    let mut p = Packet::new(UPDATE_IMAGE_V3);
    p.bool(false);
    p.str(name);
    p.i32(CHANNELS.len() as i32);
    for c in CHANNELS {
        p.str(c);
    }
    for v in [x, y, width, height] {
        p.i32(v as i32);
    }
    for offset in 0..CHANNELS.len() {
        p.i64(offset as i64);
    }
    for _ in CHANNELS {
        p.i64(CHANNELS.len() as i64);
    }
    p.0.reserve(rgb.len() * 12);
    for v in rgb.iter().flatten() {
        p.0.extend_from_slice(&v.to_le_bytes());
    }
    p.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn create_image_framing() {
        let p = create_image("a", 3, 2);
        let mut want = vec![];
        want.extend_from_slice(&(p.len() as u32).to_le_bytes());
        want.extend_from_slice(&[4, 1, b'a', 0]);
        for v in [3i32, 2, 3] {
            want.extend_from_slice(&v.to_le_bytes());
        }
        want.extend_from_slice(b"R\0G\0B\0");
        assert_eq!(p, want);
        assert_eq!(p.len(), 4 + 1 + 1 + 2 + 12 + 6);
    }

    #[test]
    fn update_image_framing() {
        let p = update_image(
            "img\0x",
            [16, 32, 2, 1],
            &[[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]],
        );
        assert_eq!(
            u32::from_le_bytes(p[..4].try_into().unwrap()) as usize,
            p.len()
        );
        assert_eq!(p[4], UPDATE_IMAGE_V3);
        assert_eq!(p[5], 0);
        // The NUL in the name is dropped, not sent as an early end.
        assert_eq!(&p[6..11], b"imgx\0");
        assert_eq!(i32::from_le_bytes(p[11..15].try_into().unwrap()), 3);
        assert_eq!(&p[15..21], b"R\0G\0B\0");
        let ints: Vec<i32> = (0..4)
            .map(|k| i32::from_le_bytes(p[21 + 4 * k..25 + 4 * k].try_into().unwrap()))
            .collect();
        assert_eq!(ints, [16, 32, 2, 1]);
        let longs: Vec<i64> = (0..6)
            .map(|k| i64::from_le_bytes(p[37 + 8 * k..45 + 8 * k].try_into().unwrap()))
            .collect();
        assert_eq!(longs, [0, 1, 2, 3, 3, 3]);
        let floats: Vec<f32> = p[85..]
            .chunks(4)
            .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
            .collect();
        assert_eq!(floats, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
    }
}
