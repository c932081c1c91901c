//! FNV-1a over a network observer's published outputs (every temperature,
//! upper bound and limit, by their bits), shared by the replays whose host
//! and firmware runs must print the same checksum.

use coil_thermal::observer::network::NetworkOutputs;

/// The FNV-1a offset basis: the checksum before any tick.
pub const START: u32 = 0x811c_9dc5;

fn fnv(mut hash: u32, bits: u32) -> u32 {
    for byte in bits.to_le_bytes() {
        hash ^= u32::from(byte);
        hash = hash.wrapping_mul(0x0100_0193);
    }
    hash
}

/// `hash` with one tick's outputs folded in.
pub fn fold<const N: usize, const M: usize, const P: usize>(
    mut hash: u32,
    o: &NetworkOutputs<N, M, P>,
) -> u32 {
    for v in o.temps_c.iter().chain(&o.upper_c) {
        hash = fnv(hash, v.to_bits());
    }
    for l in &o.limits {
        hash = fnv(hash, l.current_a.to_bits());
    }
    hash
}
