//! Warm restart: the observer's state saved to bytes and restored after a
//! reset, or refused.
//!
//! After a reset the coils may still be hot, and an observer that restarts at
//! ambient would let the controller drive them straight past their limit. So
//! the state is saved (periodically, or on a brown-out warning) to a byte
//! buffer the application keeps in retained RAM or flash, and restored at
//! boot. A snapshot that cannot be trusted is refused, and the observer then
//! starts from [`conservative_start`].
//!
//! # Format (version 2, little endian)
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `b"CTHS"` |
//! | 4 | 2 | format version |
//! | 6 | 2 | node count `N` |
//! | 8 | 4 | configuration fingerprint (see [`Fingerprint`]) |
//! | 12 | 4 | saved-at time \[s\], the application's clock |
//! | 16 | 1 | flags: bit 0 = shutdown latched, bits 1 .. 7 reserved, zero |
//! | 17 | 3 | reserved, zero |
//! | 20 | 4 N | node temperatures \[degC\], `f32` |
//! | 20 + 4 N | 4 | CRC-32 (IEEE 802.3) of every byte before it |
//!
//! Version 2 has version 1's layout; what changed is what the bytes must
//! hold: the fingerprint covers the protection as well as the model (the
//! observers' `fingerprint` docs), and the reserved bits and bytes are
//! checked. A version 1 snapshot is refused as
//! [`SnapshotError::UnsupportedVersion`] `{ found: 1 }` (its fingerprint
//! would not match anyway; the version says why): the observer then starts
//! from its conservative state.
//!
//! # What is refused
//!
//! Every check returns its own [`SnapshotError`]: a buffer too short, a wrong
//! magic, another version, another node count, a CRC mismatch (any flipped
//! bit), a reserved bit or byte that is not zero (written by another
//! format; [`SnapshotError::ReservedNotZero`]), another configuration (the
//! fingerprint of the model and protection that wrote it differs), a
//! snapshot older than the allowed age or from the future, and any
//! temperature that is not finite or outside -60 .. 400 degC.
//!
//! A latched shutdown is part of the snapshot on purpose: a reset must not be
//! a way around the latch.
//!
//! # Downtime cooling
//!
//! The saved temperatures are those at the save; a device that was off for
//! a while is cooler. Each observer's `restore_after` takes the power-off
//! time \[s\] and decays the saved state by its model's exact zero-current
//! solution over it (never below it): the modal form for the generic
//! network, bounded Taylor steps for the grid, frozen pieces of the
//! nonlinear model for the Omnimagnet. [`off_time_s`] says what an off time
//! means: capped at the snapshot's age, and *unknown* (`None`, NaN,
//! negative) is no cooling. The latch is restored as it was.

use core::fmt;

use crate::protect::alarm::AlarmState;
use crate::scalar::Scalar;
use crate::sizes::Length;

/// Format version written by [`save`].
pub const SNAPSHOT_VERSION: u16 = 2;
const MAGIC: [u8; 4] = *b"CTHS";
const HEADER_LEN: usize = 20;
const CRC_LEN: usize = 4;
const PLAUSIBLE_C: (f32, f32) = (-60.0, 400.0);

/// Bytes needed for a snapshot of `nodes` temperatures.
pub const fn snapshot_len(nodes: usize) -> usize {
    HEADER_LEN + 4 * nodes + CRC_LEN
}

/// What a snapshot carries besides the temperatures.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SnapshotMeta {
    /// Fingerprint of the configuration that wrote it.
    pub fingerprint: u32,
    /// When it was saved \[s\], on the application's clock.
    pub saved_at_s: u32,
    /// Whether the shutdown was latched.
    pub shutdown_latched: bool,
}

/// Why a snapshot was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum SnapshotError {
    /// The buffer is shorter than [`snapshot_len`] \[bytes needed\].
    BufferTooSmall {
        /// Bytes a snapshot of this size needs.
        needed: usize,
    },
    /// The first four bytes are not the snapshot magic.
    BadMagic,
    /// Written by another format version.
    UnsupportedVersion {
        /// The version found.
        found: u16,
    },
    /// A reserved flag bit or reserved byte is not zero: written by
    /// another format (or by a writer that does not follow this one).
    ReservedNotZero {
        /// Offset of the first offending byte.
        offset: usize,
    },
    /// Written for another number of nodes.
    WrongNodeCount {
        /// The node count found.
        found: u16,
    },
    /// The CRC does not match: the bytes were corrupted.
    CrcMismatch,
    /// Written by a model with another configuration.
    ConfigMismatch,
    /// Older than the allowed age \[s\].
    Stale {
        /// Its age \[s\].
        age_s: u32,
    },
    /// Saved "after" now: the application clock went backwards.
    FromFuture,
    /// A temperature is not finite or outside -60 .. 400 degC.
    ImplausibleTemperature {
        /// The node.
        node: usize,
    },
    /// The model given for the downtime cooling of a restore is not the one
    /// the observer was built from.
    CoolingModelMismatch,
}

impl fmt::Display for SnapshotError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::BufferTooSmall { needed } => write!(f, "snapshot buffer needs {needed} bytes"),
            Self::BadMagic => write!(f, "not a snapshot (bad magic)"),
            Self::UnsupportedVersion { found } => write!(
                f,
                "snapshot version {found} unsupported (this build reads version {SNAPSHOT_VERSION})"
            ),
            Self::ReservedNotZero { offset } => {
                write!(f, "snapshot reserved byte {offset} not zero")
            }
            Self::WrongNodeCount { found } => write!(f, "snapshot holds {found} nodes"),
            Self::CrcMismatch => write!(f, "snapshot CRC mismatch"),
            Self::ConfigMismatch => write!(f, "snapshot from another configuration"),
            Self::Stale { age_s } => write!(f, "snapshot is {age_s} s old"),
            Self::FromFuture => write!(f, "snapshot saved after now"),
            Self::ImplausibleTemperature { node } => {
                write!(f, "snapshot temperature of node {node} implausible")
            }
            Self::CoolingModelMismatch => {
                write!(f, "downtime cooling model differs from the observer's")
            }
        }
    }
}

impl core::error::Error for SnapshotError {}

/// CRC-32 (IEEE 802.3, reflected, init and final XOR `0xFFFF_FFFF`), bitwise:
/// 32 bytes of code instead of a 1 KiB table; snapshots are rare.
pub fn crc32(bytes: &[u8]) -> u32 {
    Crc32::new().bytes(bytes).finish()
}

#[derive(Debug, Clone, Copy)]
struct Crc32(u32);

impl Crc32 {
    const fn new() -> Self {
        Self(0xFFFF_FFFF)
    }
    fn bytes(mut self, bytes: &[u8]) -> Self {
        for byte in bytes {
            self.0 ^= *byte as u32;
            for _ in 0..8 {
                let mask = (self.0 & 1).wrapping_neg();
                self.0 = (self.0 >> 1) ^ (0xEDB8_8320 & mask);
            }
        }
        self
    }
    const fn finish(self) -> u32 {
        !self.0
    }
}

/// A configuration fingerprint: CRC-32 over the parameters that shape the
/// model, fed in a fixed order. Two configurations with equal fingerprints
/// are taken to be the same model.
#[derive(Debug, Clone, Copy)]
pub struct Fingerprint(Crc32);

impl Default for Fingerprint {
    fn default() -> Self {
        Self::new()
    }
}

impl Fingerprint {
    /// An empty fingerprint.
    pub const fn new() -> Self {
        Self(Crc32::new())
    }
    /// Feeds one `f64` parameter (its exact bits).
    #[must_use]
    pub fn f64(self, value: f64) -> Self {
        Self(self.0.bytes(&value.to_bits().to_le_bytes()))
    }
    /// Feeds a slice of `f64` parameters.
    #[must_use]
    pub fn f64s(self, values: &[f64]) -> Self {
        values.iter().fold(self, |fp, v| fp.f64(*v))
    }
    /// Feeds one integer (sizes, indices).
    #[must_use]
    pub fn u32(self, value: u32) -> Self {
        Self(self.0.bytes(&value.to_le_bytes()))
    }
    /// The fingerprint.
    pub const fn finish(self) -> u32 {
        self.0.finish()
    }
    /// The CRC register fed so far (not the finished fingerprint): what
    /// an observer's parts carry of a fingerprint still to be fed.
    pub(crate) const fn register(self) -> u32 {
        self.0 .0
    }
    /// The fingerprint whose register is `register` (see
    /// [`Self::register`]).
    pub(crate) const fn from_register(register: u32) -> Self {
        Self(Crc32(register))
    }
}

/// An observer's snapshot ([`save`]): its node estimates `temps_c`
/// \[degC\], its configuration's `fingerprint`, the time `now_s` \[s\] and
/// whether `alarm` holds the shutdown latched. One writer for every
/// observer (the grid, the Omnimagnet, the network).
///
/// # Errors
/// Those of [`save`].
pub(crate) fn save_state<S: Scalar, E: Length>(
    temps_c: &[f32],
    fingerprint: u32,
    now_s: u32,
    alarm: &AlarmState<S, E>,
    out: &mut [u8],
) -> Result<usize, SnapshotError> {
    let meta = SnapshotMeta {
        fingerprint,
        saved_at_s: now_s,
        shutdown_latched: alarm.shutdown_latched(),
    };
    save(temps_c, &meta, out)
}

/// Writes a snapshot of `temps_c` \[degC\] into `out`; returns the bytes
/// written. Never panics.
pub fn save(temps_c: &[f32], meta: &SnapshotMeta, out: &mut [u8]) -> Result<usize, SnapshotError> {
    let n = temps_c.len();
    let len = snapshot_len(n);
    let node_count = u16::try_from(n).map_err(|_| SnapshotError::WrongNodeCount { found: 0 })?;
    let out = out
        .get_mut(..len)
        .ok_or(SnapshotError::BufferTooSmall { needed: len })?;
    let (header, rest) = out.split_at_mut(HEADER_LEN);
    header[0..4].copy_from_slice(&MAGIC);
    header[4..6].copy_from_slice(&SNAPSHOT_VERSION.to_le_bytes());
    header[6..8].copy_from_slice(&node_count.to_le_bytes());
    header[8..12].copy_from_slice(&meta.fingerprint.to_le_bytes());
    header[12..16].copy_from_slice(&meta.saved_at_s.to_le_bytes());
    header[16..20].copy_from_slice(&[meta.shutdown_latched as u8, 0, 0, 0]);
    let (body, crc) = rest.split_at_mut(4 * n);
    for (chunk, t) in body.chunks_exact_mut(4).zip(temps_c) {
        chunk.copy_from_slice(&t.to_le_bytes());
    }
    let checksum = Crc32::new().bytes(header).bytes(body).finish();
    crc.copy_from_slice(&checksum.to_le_bytes());
    Ok(len)
}

/// What a restore must match.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RestorePolicy {
    /// Fingerprint of the running configuration.
    pub fingerprint: u32,
    /// Now \[s\], on the same clock as `saved_at_s`.
    pub now_s: u32,
    /// Oldest acceptable snapshot \[s\].
    pub max_age_s: u32,
}

fn read_u16(bytes: &[u8], at: usize) -> u16 {
    let mut b = [0; 2];
    if let Some(src) = bytes.get(at..at + 2) {
        b.copy_from_slice(src);
    }
    u16::from_le_bytes(b)
}

fn read_u32(bytes: &[u8], at: usize) -> u32 {
    let mut b = [0; 4];
    if let Some(src) = bytes.get(at..at + 4) {
        b.copy_from_slice(src);
    }
    u32::from_le_bytes(b)
}

/// Restores temperatures \[degC\] from a snapshot, or says why not. Never
/// panics, whatever the bytes.
pub fn restore<const N: usize>(
    bytes: &[u8],
    policy: &RestorePolicy,
) -> Result<([f32; N], SnapshotMeta), SnapshotError> {
    let mut temps_c = [0.0f32; N];
    let meta = restore_into(bytes, policy, &mut temps_c)?;
    Ok((temps_c, meta))
}

/// [`restore`] into `temps_c` \[degC\], whose length is the node count
/// the snapshot must have (an observer's of sizes read at run time); on
/// an error `temps_c` may hold part of the snapshot. Never panics,
/// whatever the bytes.
pub fn restore_into(
    bytes: &[u8],
    policy: &RestorePolicy,
    temps_c: &mut [f32],
) -> Result<SnapshotMeta, SnapshotError> {
    let n = temps_c.len();
    let len = snapshot_len(n);
    let bytes = bytes
        .get(..len)
        .ok_or(SnapshotError::BufferTooSmall { needed: len })?;
    if bytes.get(0..4) != Some(&MAGIC[..]) {
        return Err(SnapshotError::BadMagic);
    }
    let crc_at = len - CRC_LEN;
    let stored_crc = read_u32(bytes, crc_at);
    if crc32(bytes.get(..crc_at).unwrap_or(&[])) != stored_crc {
        return Err(SnapshotError::CrcMismatch);
    }
    let version = read_u16(bytes, 4);
    if version != SNAPSHOT_VERSION {
        return Err(SnapshotError::UnsupportedVersion { found: version });
    }
    let nodes = read_u16(bytes, 6);
    if nodes as usize != n {
        return Err(SnapshotError::WrongNodeCount { found: nodes });
    }
    // Flags: only bit 0 is defined; bytes 17 .. 20 are reserved.
    let flags = bytes.get(16).copied().unwrap_or(0);
    if flags & !1 != 0 {
        return Err(SnapshotError::ReservedNotZero { offset: 16 });
    }
    if let Some(offset) = (17..HEADER_LEN).find(|at| bytes.get(*at).is_some_and(|b| *b != 0)) {
        return Err(SnapshotError::ReservedNotZero { offset });
    }
    let meta = SnapshotMeta {
        fingerprint: read_u32(bytes, 8),
        saved_at_s: read_u32(bytes, 12),
        shutdown_latched: bytes.get(16).is_some_and(|f| f & 1 == 1),
    };
    if meta.fingerprint != policy.fingerprint {
        return Err(SnapshotError::ConfigMismatch);
    }
    let age_s = policy
        .now_s
        .checked_sub(meta.saved_at_s)
        .ok_or(SnapshotError::FromFuture)?;
    if age_s > policy.max_age_s {
        return Err(SnapshotError::Stale { age_s });
    }
    for (node, t) in temps_c.iter_mut().enumerate() {
        *t = f32::from_bits(read_u32(bytes, HEADER_LEN + 4 * node));
        if !(t.is_finite() && *t >= PLAUSIBLE_C.0 && *t <= PLAUSIBLE_C.1) {
            return Err(SnapshotError::ImplausibleTemperature { node });
        }
    }
    Ok(meta)
}

/// The power-off time \[s\] over which a restore decays the saved state:
/// `off_s` as the application measured it, capped at the snapshot's age
/// (`now_s - saved_at_s`: the device cannot have cooled longer than since
/// it was saved). `None` (unknown), a NaN or a negative time mean **no
/// cooling** (0 s): the saved state, which is never below the cooled one, is
/// the safe start when nothing says how long the device was off.
///
/// The state cooled over this time is only as safe as the off time: if the
/// device ran (and heated) between the save and the power-off, pass only
/// the time it was really off, or `None`.
pub fn off_time_s(off_s: Option<f32>, meta: &SnapshotMeta, policy: &RestorePolicy) -> f32 {
    let age_s = policy.now_s.saturating_sub(meta.saved_at_s) as f32;
    match off_s {
        Some(t) if t > 0.0 => t.min(age_s),
        _ => 0.0,
    }
}

/// A snapshot read back for a running configuration: its temperatures, its
/// header, and the policy it was checked against. The one read of every
/// observer's restore (the grid's, the Omnimagnet's, the network's), so
/// that each checks its snapshot and measures its age the same way.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Restored<V> {
    /// The saved node temperatures \[degC\] (an array, or a `Vec` at
    /// sizes read at run time).
    pub saved_c: V,
    /// The snapshot's header.
    pub meta: SnapshotMeta,
    /// What it was checked against.
    pub policy: RestorePolicy,
}

impl<V: AsMut<[f32]>> Restored<V> {
    /// [`restore`] of `bytes` into `saved_c` (whose length is the node
    /// count) for the configuration `fingerprint`, at `now_s` \[s\], no
    /// older than `max_age_s` \[s\].
    pub(crate) fn read(
        bytes: &[u8],
        fingerprint: u32,
        now_s: u32,
        max_age_s: u32,
        mut saved_c: V,
    ) -> Result<Self, SnapshotError> {
        let policy = RestorePolicy {
            fingerprint,
            now_s,
            max_age_s,
        };
        let meta = restore_into(bytes, &policy, saved_c.as_mut())?;
        Ok(Self {
            saved_c,
            meta,
            policy,
        })
    }

    /// The snapshot's age \[s\]: the longest the device can have been
    /// off.
    pub(crate) fn age_s(&self) -> f32 {
        self.policy.now_s.saturating_sub(self.meta.saved_at_s) as f32
    }

    /// [`off_time_s`] of the application's `off_s` \[s\] for this
    /// snapshot.
    pub(crate) fn off_time_s(&self, off_s: Option<f32>) -> f32 {
        off_time_s(off_s, &self.meta, &self.policy)
    }
}

/// The documented start when no snapshot can be trusted: every measured node
/// at its reading, and every *unmeasured* node no cooler than the hottest
/// valid reading (nor than the ambient). A coil that was hot before the reset
/// is then assumed hot until the filter learns otherwise, which errs on the
/// side of a lower current limit.
///
/// `readings_c[k]` is sensor `k`'s reading \[degC\] (None or non-finite if it
/// has none), `sensor_node[k]` the node it measures.
pub fn conservative_start<const N: usize, const P: usize>(
    readings_c: &[Option<f32>; P],
    sensor_node: &[usize; P],
    ambient_c: f32,
) -> [f32; N] {
    let mut temps_c = [0.0; N];
    conservative_start_into(readings_c, sensor_node, ambient_c, &mut temps_c);
    temps_c
}

/// [`conservative_start`] into `temps_c` \[degC\] (one per node; the
/// readings and their nodes pair up as far as both go), for sizes read at
/// run time.
pub fn conservative_start_into(
    readings_c: &[Option<f32>],
    sensor_node: &[usize],
    ambient_c: f32,
    temps_c: &mut [f32],
) {
    let valid = |r: &Option<f32>| r.filter(|t| t.is_finite());
    let hottest = readings_c
        .iter()
        .filter_map(valid)
        .fold(ambient_c, f32::max);
    let hottest = if hottest.is_finite() { hottest } else { 20.0 };
    temps_c.fill(hottest);
    for (reading, node) in readings_c.iter().zip(sensor_node) {
        if let (Some(t), Some(slot)) = (valid(reading), temps_c.get_mut(*node)) {
            *slot = t;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const POLICY: RestorePolicy = RestorePolicy {
        fingerprint: 0xC0FFEE,
        now_s: 1_000,
        max_age_s: 600,
    };

    fn saved() -> [u8; snapshot_len(4)] {
        let mut buf = [0u8; snapshot_len(4)];
        let meta = SnapshotMeta {
            fingerprint: 0xC0FFEE,
            saved_at_s: 900,
            shutdown_latched: true,
        };
        save(&[85.25, 60.0, -3.5, 41.0], &meta, &mut buf).unwrap();
        buf
    }

    #[test]
    fn crc32_matches_the_standard_check_value() {
        // The CRC catalogue's check value for "123456789".
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
    }

    #[test]
    fn round_trip_is_exact() {
        let (temps, meta) = restore::<4>(&saved(), &POLICY).unwrap();
        assert_eq!(temps, [85.25, 60.0, -3.5, 41.0]);
        assert!(meta.shutdown_latched);
        assert_eq!(meta.saved_at_s, 900);
    }

    #[test]
    fn every_single_bit_flip_is_refused() {
        let good = saved();
        for byte in 0..good.len() {
            for bit in 0..8 {
                let mut bad = good;
                bad[byte] ^= 1 << bit;
                assert!(
                    restore::<4>(&bad, &POLICY).is_err(),
                    "byte {byte} bit {bit}"
                );
            }
        }
    }

    #[test]
    fn each_mismatch_has_its_own_error() {
        let good = saved();
        assert_eq!(
            restore::<4>(&good[..10], &POLICY),
            Err(SnapshotError::BufferTooSmall { needed: 40 })
        );
        assert_eq!(
            restore::<3>(&good, &POLICY).map(|_| ()),
            Err(SnapshotError::CrcMismatch)
        );
        assert_eq!(
            restore::<4>(&[0u8; 40], &POLICY),
            Err(SnapshotError::BadMagic)
        );
        let other_config = RestorePolicy {
            fingerprint: 1,
            ..POLICY
        };
        assert_eq!(
            restore::<4>(&good, &other_config),
            Err(SnapshotError::ConfigMismatch)
        );
        let later = RestorePolicy {
            now_s: 2_000,
            ..POLICY
        };
        assert_eq!(
            restore::<4>(&good, &later),
            Err(SnapshotError::Stale { age_s: 1_100 })
        );
        let earlier = RestorePolicy {
            now_s: 100,
            ..POLICY
        };
        assert_eq!(
            restore::<4>(&good, &earlier),
            Err(SnapshotError::FromFuture)
        );
        // Valid CRC over an implausible temperature or another version.
        let meta = SnapshotMeta {
            fingerprint: 0xC0FFEE,
            saved_at_s: 900,
            shutdown_latched: false,
        };
        let mut buf = [0u8; snapshot_len(4)];
        save(&[20.0, f32::NAN, 20.0, 20.0], &meta, &mut buf).unwrap();
        assert_eq!(
            restore::<4>(&buf, &POLICY),
            Err(SnapshotError::ImplausibleTemperature { node: 1 })
        );
        let mut versioned = saved();
        versioned[4] = 9;
        let crc = crc32(&versioned[..36]);
        versioned[36..].copy_from_slice(&crc.to_le_bytes());
        assert_eq!(
            restore::<4>(&versioned, &POLICY),
            Err(SnapshotError::UnsupportedVersion { found: 9 })
        );
    }

    /// Rewrites byte `at` of a good snapshot to `value` and fixes the CRC,
    /// so that only the field's own check can refuse it.
    fn with_byte(at: usize, value: u8) -> [u8; snapshot_len(4)] {
        let mut buf = saved();
        buf[at] = value;
        let crc = crc32(&buf[..36]);
        buf[36..].copy_from_slice(&crc.to_le_bytes());
        buf
    }

    #[test]
    fn nonzero_reserved_bits_and_bytes_are_refused() {
        for bit in 1..8 {
            assert_eq!(
                restore::<4>(&with_byte(16, 1 | 1 << bit), &POLICY),
                Err(SnapshotError::ReservedNotZero { offset: 16 }),
                "flag bit {bit}"
            );
        }
        for at in 17..20 {
            for value in [1u8, 0x80, 0xFF] {
                assert_eq!(
                    restore::<4>(&with_byte(at, value), &POLICY),
                    Err(SnapshotError::ReservedNotZero { offset: at }),
                    "byte {at} = {value}"
                );
            }
        }
        // The defined bit alone is fine either way.
        assert!(restore::<4>(&with_byte(16, 0), &POLICY).is_ok());
        assert!(restore::<4>(&with_byte(16, 1), &POLICY).is_ok());
    }

    #[test]
    fn a_version_1_snapshot_is_refused_by_its_version() {
        assert_eq!(SNAPSHOT_VERSION, 2);
        let old = with_byte(4, 1);
        let refused = restore::<4>(&old, &POLICY);
        assert_eq!(refused, Err(SnapshotError::UnsupportedVersion { found: 1 }));
        let message = std::format!("{}", refused.unwrap_err());
        assert!(message.contains("version 1") && message.contains("version 2"));
    }

    #[test]
    fn off_time_is_capped_at_the_age_and_unknown_means_none() {
        let meta = SnapshotMeta {
            fingerprint: 0xC0FFEE,
            saved_at_s: 900,
            shutdown_latched: false,
        };
        // Age 100 s.
        assert_eq!(off_time_s(Some(30.5), &meta, &POLICY), 30.5);
        assert_eq!(off_time_s(Some(1e9), &meta, &POLICY), 100.0);
        assert_eq!(off_time_s(Some(f32::INFINITY), &meta, &POLICY), 100.0);
        for unknown in [None, Some(f32::NAN), Some(-1.0), Some(0.0), Some(-0.0)] {
            assert_eq!(off_time_s(unknown, &meta, &POLICY), 0.0, "{unknown:?}");
        }
        let future = SnapshotMeta {
            saved_at_s: 2_000,
            ..meta
        };
        assert_eq!(off_time_s(Some(10.0), &future, &POLICY), 0.0);
    }

    #[test]
    fn conservative_start_assumes_unmeasured_nodes_are_hot() {
        let temps: [f32; 5] =
            conservative_start(&[Some(70.0), None, Some(f32::NAN)], &[0, 2, 3], 22.0);
        assert_eq!(temps, [70.0, 70.0, 70.0, 70.0, 70.0]);
        let temps: [f32; 3] = conservative_start(&[Some(30.0), Some(55.0)], &[0, 1], 22.0);
        assert_eq!(temps, [30.0, 55.0, 55.0]);
        let cold: [f32; 2] = conservative_start(&[None], &[0], f32::NAN);
        assert_eq!(cold, [20.0, 20.0]);
    }

    mod properties {
        use super::*;
        use proptest::prelude::*;
        proptest! {
            #[test]
            fn arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..80)) {
                let _ = restore::<4>(&bytes, &POLICY);
            }
        }
    }
}
