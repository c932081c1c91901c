//! The four numbers of the HPPA coil model, and the resistance convention.
//!
//! # Per element or between two coils: the factor 2
//!
//! The HPPA report (Table 7) and its LDIA digest (Table 1) publish the same
//! fitted FDM model with different `Rx`, `Ry`: the report's are exactly twice
//! the digest's. The report tabulates the resistance *per coil element*, and
//! two neighbouring elements each contribute to the path between their
//! centres, so the resistance *between two coils* is half the per-element
//! value. `Rz` (coil to cooled base) belongs to one element in both, so it is
//! the same number in both tables.
//!
//! [`GridParams`] stores the between-coils values, and can only be made by a
//! constructor that names the convention ([`GridParams::between_coils`],
//! [`GridParams::per_element`], or [`GridParams::new`] with a
//! [`Convention`]), so a per-element table can never be read as
//! between-coils values by accident.
//!
//! The presets ([`HppaPreset`]) take all the report's sets (calculated,
//! stepwise, global, FDM fitted) in the report's per-element convention;
//! [`GridParams::FDM_FITTED_DIGEST`] enters the digest's row between coils and
//! is the same model as [`GridParams::FDM_FITTED`] (a unit test checks it).

use crate::error::BuildError;

/// How the `Rx`, `Ry` of a parameter table are meant.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Convention {
    /// Resistance between the centres of two neighbouring coils \[K/W\] (the
    /// LDIA digest's Table 1).
    BetweenCoils,
    /// Resistance held by one coil element \[K/W\], twice the between-coils
    /// value (the HPPA report's tables, Table 7 for the FDM fit).
    PerElement,
}

/// The HPPA report's parameter sets (hppa-coil-grid.md, "Parameter values").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum HppaPreset {
    /// Calculated from the geometry and material data: Rx 15.21, Ry 1.61,
    /// Rz 6.16 K/W, C 79.6 J/K (7.6 degC summed fit error).
    Calculated,
    /// RC network, stepwise fit: 8.76, 2.83, 5.47 K/W, 57.5 J/K (4.7 degC).
    StepwiseFit,
    /// RC network, global fit: 14.1, 3.02, 5.32 K/W, 56.4 J/K (4.2 degC).
    GlobalFit,
    /// The FDM model fitted to the calibration runs (report Table 7):
    /// 19.8, 6.99, 5.74 K/W, 68.7 J/K (4.2 degC). The default.
    FdmFitted,
}

/// Thermal parameters of one coil of the grid, stored between coils.
///
/// Every coil has the same capacity and the same resistance to the base.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GridParams {
    rx_between_k_per_w: f64,
    ry_between_k_per_w: f64,
    rz_k_per_w: f64,
    capacity_j_per_k: f64,
}

impl GridParams {
    /// The report's FDM fit (Table 7, per element): the default set.
    pub const FDM_FITTED: Self = Self::hppa(HppaPreset::FdmFitted);
    /// The digest's FDM fit (Table 1, between coils): Rx 9.90, Ry 3.49,
    /// Rz 5.74 K/W, C 68.7 J/K; the same model as [`GridParams::FDM_FITTED`].
    pub const FDM_FITTED_DIGEST: Self = Self::between_coils(9.90, 3.49, 5.74, 68.7);

    /// `Rx`, `Ry` between two neighbouring coils \[K/W\], `Rz` coil to base
    /// \[K/W\], capacity of one coil \[J/K\].
    pub const fn between_coils(
        rx_k_per_w: f64,
        ry_k_per_w: f64,
        rz_k_per_w: f64,
        capacity_j_per_k: f64,
    ) -> Self {
        Self {
            rx_between_k_per_w: rx_k_per_w,
            ry_between_k_per_w: ry_k_per_w,
            rz_k_per_w,
            capacity_j_per_k,
        }
    }

    /// `Rx`, `Ry` per coil element \[K/W\] (twice the between-coils value),
    /// `Rz` coil to base \[K/W\], capacity of one coil \[J/K\].
    pub const fn per_element(
        rx_k_per_w: f64,
        ry_k_per_w: f64,
        rz_k_per_w: f64,
        capacity_j_per_k: f64,
    ) -> Self {
        Self::between_coils(
            rx_k_per_w / 2.0,
            ry_k_per_w / 2.0,
            rz_k_per_w,
            capacity_j_per_k,
        )
    }

    /// Values in the named convention (see the module docs).
    pub const fn new(
        convention: Convention,
        rx_k_per_w: f64,
        ry_k_per_w: f64,
        rz_k_per_w: f64,
        capacity_j_per_k: f64,
    ) -> Self {
        match convention {
            Convention::BetweenCoils => {
                Self::between_coils(rx_k_per_w, ry_k_per_w, rz_k_per_w, capacity_j_per_k)
            }
            Convention::PerElement => {
                Self::per_element(rx_k_per_w, ry_k_per_w, rz_k_per_w, capacity_j_per_k)
            }
        }
    }

    /// One of the report's sets, read in its per-element convention.
    pub const fn hppa(preset: HppaPreset) -> Self {
        let (rx, ry, rz, c) = match preset {
            HppaPreset::Calculated => (15.21, 1.61, 6.16, 79.6),
            HppaPreset::StepwiseFit => (8.76, 2.83, 5.47, 57.5),
            HppaPreset::GlobalFit => (14.1, 3.02, 5.32, 56.4),
            HppaPreset::FdmFitted => (19.8, 6.99, 5.74, 68.7),
        };
        Self::per_element(rx, ry, rz, c)
    }

    /// Resistance between two in-row neighbours \[K/W\].
    pub const fn rx_between_coils_k_per_w(&self) -> f64 {
        self.rx_between_k_per_w
    }
    /// Resistance between two cross-row neighbours \[K/W\].
    pub const fn ry_between_coils_k_per_w(&self) -> f64 {
        self.ry_between_k_per_w
    }
    /// Resistance from a coil to the cooled base \[K/W\].
    pub const fn rz_k_per_w(&self) -> f64 {
        self.rz_k_per_w
    }
    /// Heat capacity of one coil \[J/K\].
    pub const fn capacity_j_per_k(&self) -> f64 {
        self.capacity_j_per_k
    }
    /// Conductance between two in-row neighbours, `1 / Rx` \[W/K\].
    pub fn gx_w_per_k(&self) -> f64 {
        1.0 / self.rx_between_k_per_w
    }
    /// Conductance between two cross-row neighbours, `1 / Ry` \[W/K\].
    pub fn gy_w_per_k(&self) -> f64 {
        1.0 / self.ry_between_k_per_w
    }
    /// Conductance from a coil to the base, `1 / Rz` \[W/K\].
    pub fn gz_w_per_k(&self) -> f64 {
        1.0 / self.rz_k_per_w
    }

    /// Every resistance finite and > 0 K/W, the capacity finite and > 0 J/K.
    pub fn validate(&self) -> Result<(), BuildError> {
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !positive(self.rx_between_k_per_w) {
            return Err(BuildError::InvalidParameter { name: "rx_k_per_w" });
        }
        if !positive(self.ry_between_k_per_w) {
            return Err(BuildError::InvalidParameter { name: "ry_k_per_w" });
        }
        if !positive(self.rz_k_per_w) {
            return Err(BuildError::InvalidParameter { name: "rz_k_per_w" });
        }
        if !positive(self.capacity_j_per_k) {
            return Err(BuildError::InvalidCapacity { node: 0 });
        }
        Ok(())
    }
}

impl Default for GridParams {
    /// [`GridParams::FDM_FITTED`].
    fn default() -> Self {
        Self::FDM_FITTED
    }
}
