//! The paper's tables as `const` data (Esmailie et al. 2021, Tables 1-7 and
//! Appendix A), converted once from cm, cm^2, cm^3 and kJ to SI.
//!
//! Another Omnimagnet is another [`OmnimagnetGeometry`] value, not new code:
//! the models only read these tables. Node indices are 0-based here (the
//! paper's element `i` is node `i - 1`); the ambient (paper's node 0) is the
//! one boundary, [`Peer::Ambient`].

/// Number of state nodes (the paper's 16 elements).
pub const NODES: usize = 16;
/// Number of solenoids (current inputs).
pub const SOLENOIDS: usize = 3;
/// Number of convection correction-factor groups (Table 7).
pub const CONVECTION_GROUPS: usize = 3;

const fn cm(x: f64) -> f64 {
    x * 1e-2
}
const fn cm2(x: f64) -> f64 {
    x * 1e-4
}
const fn cm3(x: f64) -> f64 {
    x * 1e-6
}

/// A material property as a quadratic in absolute temperature:
/// `c0 + c1 T + c2 T^2` with `T` in kelvin (the form of Eq. A1 and A2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KelvinPoly {
    /// Constant term (in the property's unit).
    pub c0: f64,
    /// Linear coefficient (property unit per K).
    pub c1: f64,
    /// Quadratic coefficient (property unit per K^2).
    pub c2: f64,
}

impl KelvinPoly {
    /// A temperature-independent property.
    pub const fn constant(value: f64) -> Self {
        Self {
            c0: value,
            c1: 0.0,
            c2: 0.0,
        }
    }

    /// The property at `temp_k` \[K\].
    #[inline]
    pub fn at_k(&self, temp_k: f64) -> f64 {
        self.c0 + temp_k * (self.c1 + temp_k * self.c2)
    }
}

/// A solid (or the trapped air) as Table 2 lists it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Material {
    /// Specific heat \[J/(kg K)\] as a function of T \[K\].
    pub specific_heat_j_per_kg_k: KelvinPoly,
    /// Density \[kg/m^3\].
    pub density_kg_per_m3: f64,
    /// Thermal conductivity \[W/(m K)\] as a function of T \[K\].
    pub conductivity_w_per_m_k: KelvinPoly,
    /// Total hemispherical emissivity (0 where the paper gives none).
    pub emissivity: f64,
}

/// Aluminium frames.
pub const ALUMINIUM: Material = Material {
    specific_heat_j_per_kg_k: KelvinPoly::constant(896.0),
    density_kg_per_m3: 2700.0,
    conductivity_w_per_m_k: KelvinPoly::constant(210.0),
    emissivity: 0.03,
};
/// Copper wire: `c_p` from Eq. A1, `k` from Eq. A2 (T in kelvin).
pub const COPPER: Material = Material {
    specific_heat_j_per_kg_k: KelvinPoly {
        c0: 316.21,
        c1: 0.3177,
        c2: -3.5e-4,
    },
    density_kg_per_m3: 8960.0,
    conductivity_w_per_m_k: KelvinPoly {
        c0: 420.75,
        c1: -0.068493,
        c2: 0.0,
    },
    emissivity: 0.78,
};
/// Polyamide wire insulation.
pub const POLYAMIDE: Material = Material {
    specific_heat_j_per_kg_k: KelvinPoly::constant(1670.0),
    density_kg_per_m3: 1140.0,
    conductivity_w_per_m_k: KelvinPoly::constant(0.25),
    emissivity: 0.6,
};
/// Ferromagnetic core alloy.
pub const CORE_ALLOY: Material = Material {
    specific_heat_j_per_kg_k: KelvinPoly::constant(502.0),
    density_kg_per_m3: 8165.57,
    conductivity_w_per_m_k: KelvinPoly::constant(13.0),
    emissivity: 0.0,
};
/// Polyurethane cover insulation.
pub const POLYURETHANE: Material = Material {
    specific_heat_j_per_kg_k: KelvinPoly::constant(1800.0),
    density_kg_per_m3: 1200.0,
    conductivity_w_per_m_k: KelvinPoly::constant(0.024),
    emissivity: 0.9,
};
/// Trapped air (its conductivity is unused: the air exchanges heat by
/// convection only, Eq. 1).
pub const TRAPPED_AIR: Material = Material {
    specific_heat_j_per_kg_k: KelvinPoly::constant(1007.0),
    density_kg_per_m3: 1.614,
    conductivity_w_per_m_k: KelvinPoly::constant(0.0263),
    emissivity: 0.0,
};
/// Insulating paper.
pub const PAPER_SHEET: Material = Material {
    specific_heat_j_per_kg_k: KelvinPoly::constant(1336.0),
    density_kg_per_m3: 950.0,
    conductivity_w_per_m_k: KelvinPoly::constant(0.143),
    emissivity: 0.95,
};

/// Which natural-convection correlation an exposed surface uses (Table 5,
/// rows as the cited references have them).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Correlation {
    /// Catton's enclosure correlation `Nu = 0.18 (Pr/(0.2+Pr) Ra)^0.29`,
    /// floored at `Nu = 1` (pure conduction across the gap).
    CattonEnclosure,
    /// Churchill-Chu, vertical surface, all Ra.
    ChurchillChuVertical,
    /// Hot horizontal plate facing up: `Nu = 0.54 Ra^(1/4)`.
    PlateFacingUp,
    /// Hot horizontal plate facing down: `Nu = 0.52 Ra^(1/5)`.
    PlateFacingDown,
}

/// The correction-factor group of a convective surface (Table 7).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ConvectionGroup {
    /// To the inside (trapped) air: elements 4, 5, 8, 10, 15.
    InsideAir = 0,
    /// To the ambient, vertical or channel surfaces: elements 6, 7, 9, 12, 13.
    AmbientVertical = 1,
    /// To the ambient, horizontal plates: elements 11, 16.
    AmbientHorizontal = 2,
}

impl ConvectionGroup {
    /// Index into per-group arrays.
    pub const fn index(self) -> usize {
        self as usize
    }
}

/// How one element's exposed surface exchanges heat with a fluid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceConvection {
    /// The correlation.
    pub correlation: Correlation,
    /// Characteristic length \[m\] (an estimate: the paper gives none).
    pub length_m: f64,
    /// The correction-factor group.
    pub group: ConvectionGroup,
}

/// One lumped element (Table 1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Element {
    /// Volume \[m^3\].
    pub volume_m3: f64,
    /// Material.
    pub material: Material,
    /// Conduction thickness per direction x, y, z \[m\] (Table 4).
    pub thickness_m: [f64; 3],
    /// Its convective surface, if it touches the inside air or the ambient.
    pub convection: Option<SurfaceConvection>,
}

/// The other side of a contact.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Peer {
    /// Another state node (0-based index).
    Node(usize),
    /// The ambient air (the paper's node 0), the model's one boundary.
    Ambient,
}

/// One row of the contact-area table (Table 3) with its conduction
/// correction factors (Table 6; 1 where none was fitted).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Contact {
    /// First node (0-based).
    pub node: usize,
    /// Second node or the ambient.
    pub peer: Peer,
    /// Contact area per direction x, y, z \[m^2\].
    pub area_m2: [f64; 3],
    /// Conduction correction factor per direction (unused for convection).
    pub conduction_cf: [f64; 3],
}

/// An element that radiates to the surroundings (view factor 1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Radiator {
    /// The node whose temperature drives the radiation.
    pub node: usize,
    /// Radiating area \[m^2\].
    pub area_m2: f64,
    /// Emissivity.
    pub emissivity: f64,
}

/// How a radiator's exchange with the surroundings is written. The paper
/// prints two forms of the same term, and they differ by a factor of about 4
/// near the ambient (the tangent of `T^4` is `4 T^3`); at 3 A after 60 min
/// Eq. 1 radiates 4-5 times what Appendix B does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RadiationForm {
    /// Eq. 1: `sigma eps S (T^4 - T_0^4)`, kelvin: the Stefan-Boltzmann law
    /// at the printed emissivities. Reads the paper's 3 A figure 11 % and
    /// 21 % cold on the middle and outer solenoids.
    StefanBoltzmann,
    /// Appendix B: the radiative conductance `sigma eps S T_0^3` of the
    /// paper's state-space form (its `G` vector holds it, and `A_ii` is the
    /// sum of the row's conductances, ambient included), so
    /// `sigma eps S T_0^3 (T - T_0)`, `T_0` in kelvin. [`PAPER_OMNIMAGNET`]'s:
    /// the form that meets the paper's 3 A figure and its 3.8 A run, and the
    /// hotter one (see the module docs of [`super`]).
    AppendixB,
}

/// A solenoid's resistance, Eq. A3: `R(T) = R0 (1 + alpha0 (T - T_ref))`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Solenoid {
    /// The node the winding heats.
    pub node: usize,
    /// `R0` \[ohm\] at `t_ref_k`.
    pub r0_ohm: f64,
    /// `alpha0` \[1/K\].
    pub alpha0_per_k: f64,
    /// Reference temperature \[K\] (293.15 K in Eq. A3).
    pub t_ref_k: f64,
}

/// Everything that describes one Omnimagnet: the tables, nothing else.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OmnimagnetGeometry {
    /// The 16 elements, in node order.
    pub elements: [Element; NODES],
    /// Contacts (conductive between solids, convective with the inside air
    /// node or the ambient).
    pub contacts: &'static [Contact],
    /// Elements radiating to the surroundings.
    pub radiators: &'static [Radiator],
    /// The form of their exchange.
    pub radiation: RadiationForm,
    /// The three solenoids, in current-input order.
    pub solenoids: [Solenoid; SOLENOIDS],
    /// The trapped-air node: contacts with it are convective.
    pub inside_air_node: usize,
    /// Fitted convection correction factor per [`ConvectionGroup`] (Table 7).
    pub convection_cf: [f64; CONVECTION_GROUPS],
}

const fn solid(v_cm3: f64, material: Material, dx_cm: [f64; 3]) -> Element {
    Element {
        volume_m3: cm3(v_cm3),
        material,
        thickness_m: [cm(dx_cm[0]), cm(dx_cm[1]), cm(dx_cm[2])],
        convection: None,
    }
}

const fn exposed(
    v_cm3: f64,
    material: Material,
    dx_cm: [f64; 3],
    correlation: Correlation,
    length_cm: f64,
    group: ConvectionGroup,
) -> Element {
    let mut e = solid(v_cm3, material, dx_cm);
    e.convection = Some(SurfaceConvection {
        correlation,
        length_m: cm(length_cm),
        group,
    });
    e
}

const fn contact(i: usize, j: usize, s_cm2: [f64; 3], cf: [f64; 3]) -> Contact {
    Contact {
        node: i - 1,
        peer: if j == 0 {
            Peer::Ambient
        } else {
            Peer::Node(j - 1)
        },
        area_m2: [cm2(s_cm2[0]), cm2(s_cm2[1]), cm2(s_cm2[2])],
        conduction_cf: cf,
    }
}

const ONE: [f64; 3] = [1.0; 3];

/// Characteristic length \[cm\] of the inside-air (Catton) correlation, an
/// estimate (the paper gives none): the gap width between the two walls of
/// the trapped-air cavity, `2 V_air / A_wetted` = 2 x 294 cm^3 / 1000 cm^2
/// (the sum of all contact areas with node 14) = 0.59 cm. At this width
/// `Ra < 1e3`, so the `Nu >= 1` conduction floor is what acts.
pub const INSIDE_GAP_CM: f64 = 2.0 * 294.0 / 1000.0;
/// Characteristic length \[cm\] of the horizontal plates, an estimate:
/// `A/P` of elements 11 and 16 (160 cm^2 each) taken as squares,
/// `sqrt(160)/4` = 3.16 cm.
pub const PLATE_LENGTH_CM: f64 = 3.162;
/// Characteristic length \[cm\] of the vertical surfaces with no extent in
/// their own thickness row (frame 3, wire insulation 3), an estimate: the
/// outer solenoid's extent, 12.1 cm (Table 4, j = 3, y).
pub const OUTER_HEIGHT_CM: f64 = 12.1;

use ConvectionGroup::{AmbientHorizontal, AmbientVertical, InsideAir};
use Correlation::{CattonEnclosure, ChurchillChuVertical, PlateFacingDown, PlateFacingUp};

/// Table 3 with Table 6's factors. CF_5,12 is printed with index 3 (z) but
/// labelled "y"; the only 5-12 contact is in y (3.6 cm^2), and a factor on a
/// zero area has zero gradient in the fit, so it could not have been fitted:
/// it is applied to y.
const PAPER_CONTACTS: [Contact; 33] = [
    contact(1, 8, [112.0, 179.0, 177.0], ONE),
    contact(1, 9, [0.0, 228.0, 232.0], ONE),
    contact(2, 10, [266.0, 38.0, 294.0], ONE),
    contact(2, 11, [326.0, 0.0, 285.0], ONE),
    contact(3, 12, [381.0, 362.0, 72.0], ONE),
    contact(3, 13, [422.0, 403.0, 0.0], ONE),
    contact(4, 5, [8.0, 0.0, 0.0], ONE),
    contact(4, 8, [0.0, 95.0, 20.0], [1.0, 0.41, 0.33]),
    contact(4, 14, [11.0, 90.0, 12.0], ONE),
    contact(4, 15, [0.0, 17.0, 0.0], [1.0, 0.04, 1.0]),
    contact(5, 6, [5.0, 0.0, 0.0], [0.88, 1.0, 1.0]),
    contact(5, 8, [47.0, 0.0, 0.0], [0.88, 1.0, 1.0]),
    contact(5, 10, [138.0, 0.0, 14.0], [0.13, 1.0, 0.30]),
    contact(5, 12, [0.0, 3.6, 0.0], [1.0, 0.60, 1.0]),
    contact(5, 14, [65.0, 27.0, 43.0], ONE),
    contact(6, 0, [43.0, 157.0, 29.3], ONE),
    contact(6, 7, [0.0, 6.0, 0.0], [1.0, 0.03, 1.0]),
    contact(6, 10, [0.0, 5.4, 0.0], [1.0, 0.95, 1.0]),
    contact(6, 12, [15.0, 155.0, 0.0], [0.05, 0.18, 1.0]),
    contact(7, 0, [6.0, 36.0, 172.0], ONE),
    contact(7, 12, [0.0, 0.0, 9.0], ONE),
    contact(7, 16, [0.0, 0.0, 43.0], ONE),
    contact(8, 14, [0.0, 90.0, 151.0], ONE),
    contact(9, 0, [0.0, 134.0, 0.0], ONE),
    contact(9, 10, [0.0, 0.0, 177.0], ONE),
    contact(10, 14, [72.0, 0.0, 220.0], ONE),
    contact(11, 0, [0.0, 0.0, 160.0], ONE),
    contact(11, 12, [242.0, 0.0, 0.0], ONE),
    contact(11, 16, [0.0, 0.0, 180.0], ONE),
    contact(12, 0, [0.0, 178.0, 0.0], ONE),
    contact(13, 0, [436.0, 577.0, 36.0], ONE),
    contact(15, 14, [73.0, 73.0, 73.0], ONE),
    contact(16, 0, [0.0, 0.0, 160.0], ONE),
];

/// Exposed area of cover insulation 3 \[cm^2\] (Table 3, 13-0): solenoid 3
/// radiates through this transparent cover, so it shares the area.
const COVER_3_AREA_CM2: f64 = 436.0 + 577.0 + 36.0;

/// Radiation as the paper keeps it (view factor 1): frame 4, wire insulation
/// 3, cover insulation 3 and the paper, each over its ambient contact area
/// (Table 3, `i-0`). The paper also lists solenoid 3 "through its
/// transparent cover", over the same surface as cover insulation 3; counting
/// both would make that surface emit 0.78 + 0.9 = 1.68 black bodies. The
/// paper gives the cover an emissivity of 0.9, so by Kirchhoff's law it
/// absorbs 90 % of thermal radiation and cannot also pass the solenoid's:
/// the surface radiates once, at the cover's emissivity and temperature (the
/// hotter reading of the two: the solenoid's own radiation would leave from
/// a hotter node; measured in the module docs' sensitivity table).
const PAPER_RADIATORS: [Radiator; 4] = [
    Radiator {
        node: 6,
        area_m2: cm2(6.0 + 36.0 + 172.0),
        emissivity: ALUMINIUM.emissivity,
    },
    Radiator {
        node: 11,
        area_m2: cm2(178.0),
        emissivity: POLYAMIDE.emissivity,
    },
    Radiator {
        node: 12,
        area_m2: cm2(COVER_3_AREA_CM2),
        emissivity: POLYURETHANE.emissivity,
    },
    Radiator {
        node: 15,
        area_m2: cm2(160.0),
        emissivity: PAPER_SHEET.emissivity,
    },
];

/// Solenoid 3 radiating through a transparent cover 3, as the paper lists it
/// (emissivity of heated copper, cover 3's exposed area): not part of
/// [`PAPER_OMNIMAGNET`] (see its radiators), kept for the sensitivity study.
pub const SOLENOID_3_RADIATOR: Radiator = Radiator {
    node: 2,
    area_m2: cm2(COVER_3_AREA_CM2),
    emissivity: COPPER.emissivity,
};

/// The fitted convection correction factors of Table 7 (inside air 1.96,
/// ambient vertical 2.74, ambient horizontal 2.88), per
/// [`ConvectionGroup`]. Fitted to the paper's own implementation of Eq. 1;
/// on this crate's energy-conserving network they over-cool the device by
/// about 40 K after 2 h at 3.8 A, so [`PAPER_OMNIMAGNET`] does not apply
/// them (see the module docs of [`super`]).
pub const TABLE_7_CONVECTION_CF: [f64; CONVECTION_GROUPS] = [1.96, 2.74, 2.88];

const fn solenoid(node: usize, r0_ohm: f64) -> Solenoid {
    Solenoid {
        node,
        r0_ohm,
        alpha0_per_k: 0.0039,
        t_ref_k: 293.15,
    }
}

/// The Omnimagnet of Esmailie et al. (2021), with the fitted correction
/// factors of Table 6 (conduction); Table 7 is not applied (see
/// [`TABLE_7_CONVECTION_CF`]); radiation in the form of Appendix B
/// ([`RadiationForm::AppendixB`]).
///
/// Vertical lengths: an element's own extent where its thickness row holds
/// one (frame 4: 14.3 cm in y; cover 1: 10.06 cm in x; cover 3: 13.67 cm in
/// z), else [`OUTER_HEIGHT_CM`]. Plates: element 11 is taken as the upper
/// face (facing up) and the paper as the lower face (facing down); the paper
/// does not say which is which.
pub const PAPER_OMNIMAGNET: OmnimagnetGeometry = OmnimagnetGeometry {
    elements: [
        solid(326.0, COPPER, [10.0, 1.4, 1.4]),
        solid(285.0, COPPER, [0.8, 11.9, 0.8]),
        solid(320.0, COPPER, [0.7, 12.1, 0.7]),
        exposed(
            2.0 * 27.77,
            ALUMINIUM,
            [10.0, 0.6, 2.0],
            CattonEnclosure,
            INSIDE_GAP_CM,
            InsideAir,
        ),
        exposed(
            2.0 * 31.95,
            ALUMINIUM,
            [0.5, 12.7, 1.1],
            CattonEnclosure,
            INSIDE_GAP_CM,
            InsideAir,
        ),
        exposed(
            2.0 * 25.46,
            ALUMINIUM,
            [1.1, 0.3, 1.2],
            ChurchillChuVertical,
            OUTER_HEIGHT_CM,
            AmbientVertical,
        ),
        exposed(
            2.0 * 46.18,
            ALUMINIUM,
            [1.2, 14.3, 0.6],
            ChurchillChuVertical,
            14.3,
            AmbientVertical,
        ),
        exposed(
            54.9,
            POLYAMIDE,
            [0.6, 0.08, 0.08],
            CattonEnclosure,
            INSIDE_GAP_CM,
            InsideAir,
        ),
        exposed(
            4.2,
            POLYURETHANE,
            [10.06, 0.02, 0.02],
            ChurchillChuVertical,
            10.06,
            AmbientVertical,
        ),
        exposed(
            47.6,
            POLYAMIDE,
            [0.05, 0.7, 0.05],
            CattonEnclosure,
            INSIDE_GAP_CM,
            InsideAir,
        ),
        exposed(
            5.5,
            POLYURETHANE,
            [0.02, 12.11, 0.02],
            PlateFacingUp,
            PLATE_LENGTH_CM,
            AmbientHorizontal,
        ),
        exposed(
            52.4,
            POLYAMIDE,
            [0.04, 0.04, 0.8],
            ChurchillChuVertical,
            OUTER_HEIGHT_CM,
            AmbientVertical,
        ),
        exposed(
            6.9,
            POLYURETHANE,
            [0.02, 0.02, 13.67],
            ChurchillChuVertical,
            13.67,
            AmbientVertical,
        ),
        solid(294.0, TRAPPED_AIR, [0.0, 0.0, 0.0]),
        exposed(
            525.0,
            CORE_ALLOY,
            [4.5, 3.7, 4.5],
            CattonEnclosure,
            INSIDE_GAP_CM,
            InsideAir,
        ),
        exposed(
            2.9,
            PAPER_SHEET,
            [10.06, 7.51, 0.01],
            PlateFacingDown,
            PLATE_LENGTH_CM,
            AmbientHorizontal,
        ),
    ],
    contacts: &PAPER_CONTACTS,
    radiators: &PAPER_RADIATORS,
    radiation: RadiationForm::AppendixB,
    solenoids: [solenoid(0, 3.2), solenoid(1, 2.8), solenoid(2, 3.1)],
    inside_air_node: 13,
    convection_cf: [1.0; CONVECTION_GROUPS],
};
