//! The scalar types of PLY properties, and how binary records encode them (either byte order).

/// A scalar type of the PLY header.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    pub(super) fn parse(name: &str) -> Option<Scalar> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    #[inline]
    pub(super) fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    pub(super) fn is_integer(self) -> bool {
        !matches!(self, Scalar::F32 | Scalar::F64)
    }

    /// The value at the start of `b` (which holds at least `size()` bytes).
    #[inline(always)]
    pub(super) fn f64(self, b: &[u8], big: bool) -> f64 {
        match self {
            Scalar::F32 => f32::from_bits(u32_at(b, big)) as f64,
            Scalar::F64 => f64::from_bits(u64_at(b, big)),
            _ => self.i64(b, big) as f64,
        }
    }

    /// The integer at the start of `b` (floats are truncated; the header allows only integer
    /// types where this is used).
    #[inline(always)]
    pub(super) fn i64(self, b: &[u8], big: bool) -> i64 {
        match self {
            Scalar::I8 => b[0] as i8 as i64,
            Scalar::U8 => b[0] as i64,
            Scalar::I16 => u16_at(b, big) as i16 as i64,
            Scalar::U16 => u16_at(b, big) as i64,
            Scalar::I32 => u32_at(b, big) as i32 as i64,
            Scalar::U32 => u32_at(b, big) as i64,
            Scalar::F32 | Scalar::F64 => self.f64(b, big) as i64,
        }
    }
}

#[inline(always)]
fn u16_at(b: &[u8], big: bool) -> u16 {
    let a = [b[0], b[1]];
    if big {
        u16::from_be_bytes(a)
    } else {
        u16::from_le_bytes(a)
    }
}

#[inline(always)]
pub(super) fn u32_at(b: &[u8], big: bool) -> u32 {
    let a: [u8; 4] = b[..4].try_into().expect("4 bytes");
    if big {
        u32::from_be_bytes(a)
    } else {
        u32::from_le_bytes(a)
    }
}

#[inline(always)]
fn u64_at(b: &[u8], big: bool) -> u64 {
    let a: [u8; 8] = b[..8].try_into().expect("8 bytes");
    if big {
        u64::from_be_bytes(a)
    } else {
        u64::from_le_bytes(a)
    }
}
