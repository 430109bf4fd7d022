//! Cryptomatte (Psyop specification 1.1): per pixel, the objects and materials seen and their
//! coverage, as ranked (id, coverage) pairs in `CryptoObject00…02` and `CryptoMaterial00…02`
//! (RGBA = id, coverage, id, coverage: six ranks), with the names' hashes in the header.
//! Coverage is the share of the pixel's camera samples that hit the object; the samples are
//! drawn from the pixel filter, so this is the filter-weighted coverage the specification
//! asks for.

use std::collections::BTreeMap;

/// Layers per kind (two ranks each).
pub const LAYERS: u8 = 3;

/// The two kinds of matte.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Kind {
    Object,
    Material,
}

impl Kind {
    /// The type name: the layer prefix and the `cryptomatte/<key>/name` value.
    pub fn type_name(self) -> &'static str {
        match self {
            Self::Object => "CryptoObject",
            Self::Material => "CryptoMaterial",
        }
    }
}

/// MurmurHash3, x86 32-bit variant, seed 0: the hash the specification names.
pub fn murmur3_32(data: &[u8]) -> u32 {
    const C1: u32 = 0xcc9e_2d51;
    const C2: u32 = 0x1b87_3593;
    let mut h: u32 = 0;
    let mut chunks = data.chunks_exact(4);
    for chunk in &mut chunks {
        let k = u32::from_le_bytes([chunk[0], chunk[1], chunk[2], chunk[3]]);
        h ^= k.wrapping_mul(C1).rotate_left(15).wrapping_mul(C2);
        h = h.rotate_left(13).wrapping_mul(5).wrapping_add(0xe654_6b64);
    }
    let tail = chunks.remainder();
    if !tail.is_empty() {
        let mut k = 0u32;
        for (i, &b) in tail.iter().enumerate() {
            k |= (b as u32) << (8 * i);
        }
        h ^= k.wrapping_mul(C1).rotate_left(15).wrapping_mul(C2);
    }
    h ^= data.len() as u32;
    h ^= h >> 16;
    h = h.wrapping_mul(0x85eb_ca6b);
    h ^= h >> 13;
    h = h.wrapping_mul(0xc2b2_ae35);
    h ^ (h >> 16)
}

/// The id of `name` as the bits of the float stored in the layers: its hash with the
/// exponent kept away from 0 and 255, so that the float is neither denormal, infinite nor
/// NaN (the specification's `uint32_to_float32` conversion).
pub fn id(name: &str) -> u32 {
    let h = murmur3_32(name.as_bytes());
    let exponent = (h >> 23) & 0xff;
    if exponent == 0 || exponent == 255 {
        h ^ (1 << 23)
    } else {
        h
    }
}

/// The header attributes of one kind: `cryptomatte/<key>/{name,hash,conversion,manifest}`,
/// the key being the first 7 hex digits of the type name's hash.
pub fn header_attributes(kind: Kind, names: &[String]) -> Vec<(String, String)> {
    let key = format!("{:08x}", murmur3_32(kind.type_name().as_bytes()));
    let key = &key[..7];
    let manifest: BTreeMap<&str, String> = names
        .iter()
        .map(|n| (n.as_str(), format!("{:08x}", id(n))))
        .collect();
    let attr = |field: &str| format!("cryptomatte/{key}/{field}");
    vec![
        (attr("name"), kind.type_name().into()),
        (attr("hash"), "MurmurHash3_32".into()),
        (attr("conversion"), "uint32_to_float32".into()),
        (
            attr("manifest"),
            serde_json::to_string(&manifest).expect("strings serialise"),
        ),
    ]
}

/// The ids of a render's objects and materials, by index.
#[derive(Clone, Debug, Default)]
pub struct Ids {
    pub objects: Vec<u32>,
    pub materials: Vec<u32>,
}

impl Ids {
    /// Ids of the named objects and materials.
    pub fn new(objects: &[String], materials: &[String]) -> Self {
        Self {
            objects: objects.iter().map(|n| id(n)).collect(),
            materials: materials.iter().map(|n| id(n)).collect(),
        }
    }

    /// The id table of `kind`.
    pub fn of(&self, kind: Kind) -> &[u32] {
        match kind {
            Kind::Object => &self.objects,
            Kind::Material => &self.materials,
        }
    }
}

/// Counts of samples per index (object or material) in one pixel.
pub type Counts = Vec<(u32, u32)>;

/// Adds one sample of `index` to `counts`.
#[inline]
pub fn count(counts: &mut Counts, index: u32, n: u32) {
    match counts.iter_mut().find(|(i, _)| *i == index) {
        Some((_, c)) => *c += n,
        None => counts.push((index, n)),
    }
}

/// The ranked (id bits, coverage) pairs of a pixel whose `samples` samples hit the indices
/// in `counts`: ids (several names may share one) merged, by coverage, highest first.
pub fn ranks(counts: &Counts, ids: &[u32], samples: u32) -> Vec<(u32, f32)> {
    let mut by_id: Vec<(u32, u32)> = Vec::with_capacity(counts.len());
    for &(index, n) in counts {
        count(&mut by_id, ids[index as usize], n);
    }
    by_id.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
    by_id
        .into_iter()
        .map(|(id, n)| (id, n as f32 / samples.max(1) as f32))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reference values of MurmurHash3_x86_32 with seed 0.
    #[test]
    fn murmur3_matches_the_reference() {
        assert_eq!(murmur3_32(b""), 0);
        assert_eq!(murmur3_32(b"hello"), 0x248b_fa47);
        assert_eq!(
            murmur3_32(b"The quick brown fox jumps over the lazy dog"),
            0x2e4f_f723
        );
    }

    #[test]
    fn ids_are_normal_floats() {
        for name in [
            "",
            "a",
            "floor",
            "/World/Key",
            "tall_block",
            "x".repeat(100).as_str(),
        ] {
            let f = f32::from_bits(id(name));
            assert!(f.is_normal(), "{name}: {f}");
        }
    }

    #[test]
    fn ranks_merge_shared_ids_and_sort_by_coverage() {
        let ids = [7, 9, 7];
        let r = ranks(&vec![(0, 2), (1, 5), (2, 4)], &ids, 11);
        assert_eq!(r, [(7, 6.0 / 11.0), (9, 5.0 / 11.0)]);
    }
}
