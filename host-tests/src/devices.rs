//! The library's device models as host plants and model files: the HPPA
//! coil grid and the Omnimagnet.
//!
//! # HPPA grid: as a model file
//!
//! `CoilGrid<S, ROWS, COLS>` has compile-time sizes. The host runs the grid
//! as a model file instead: [`grid_file`] builds the library grid for one of
//! the sizes in [`GRID_SIZES`] (a fixed set, other sizes are refused with a
//! clear message), takes its network with `CoilGrid::to_network`, and writes
//! every link as a named conductance, so the grid is simulated, replayed,
//! calibrated and analysed by the same code as any model file: the
//! library's `RunTimeStepper` (simulate, calibrate) and `RunTimeObserver`
//! (replay, faults) at the grid's own size. It is the grid's physics with
//! another integrator than `CoilGrid::tick` (no multi-rate accounting;
//! `tests/grid_replay.rs` bounds the grid stepper against an independent
//! reference).
//!
//! Names: nodes `coil_r{row}_c{col}` (0-based), inputs `coil_r{row}_c{col}`
//! reading trace columns `I_r{row}_c{col}_a` (the committed traces'),
//! boundaries `coolant` (the cooled base, through `Rz`) and `ambient` (the
//! report's padding cells), both 20 degC unless a trace column or
//! `--ambient-c` says otherwise. Every coil's critical temperature is
//! [`HPPA_CRITICAL_C`] (100 degC).
//!
//! Conductances carry the grid parameter they come from in their name:
//! `gx:A-B` (in-row link through `Rx`), `gy:A-B` (cross-row link through
//! `Ry`), `gz:A-coolant` (through `Rz`), and `gx:A-ambient`, `gy:A-ambient`
//! for the padding links, with `factor` = the number of padding links of
//! that kind (so `G = factor / R`). Each is written as `r_k_per_w`, the
//! resistance *between two coils* (the convention `GridParams` stores, the
//! LDIA digest's Table 1: half the report's per-element `Rx`, `Ry`; `Rz` is
//! the same in both). Calibration parameters `grid.rx_k_per_w`,
//! `grid.ry_k_per_w`, `grid.rz_k_per_w` and `grid.capacity_j_per_k` set every
//! conductance of their kind, or every node's capacity, at once
//! ([`access_grid_param`]).
//!
//! # Omnimagnet: the nonlinear model
//!
//! [`OmnimagnetPlant`] steps the paper's nonlinear 16-node model with its own
//! `step_rk4` (capacities, conduction, convection and radiation at the
//! present temperatures) in sub-steps of at most [`OMNIMAGNET_MAX_STEP_S`].
//! [`omnimagnet_file`] is the network linearised at a uniform temperature
//! (for replay, limits, calibration and `--write-model`).

use anyhow::{bail, Context, Result};
use coil_thermal::grid::{CoilGrid, GridConfig, GridParams, HppaPreset};
use coil_thermal::omnimagnet::{
    Omnimagnet, Preset, CRITICAL_TEMPS_C, NODES, NODE_NAMES, SOLENOIDS,
};
use coil_thermal::protect::derating::HPPA_CRITICAL_C;

use crate::model_file::{
    BoundarySpec, ConductanceSpec, InitialSpec, ModelFile, NodeSpec, SourceSpec,
};
use crate::sim::{Channel, Plant, PlantInfo};

/// The grid sizes (rows, columns) the host tool instantiates: the report's
/// 7 x 12 (84 coils, the default), its transposes and halves, and small
/// grids for tests.
pub const GRID_SIZES: [(usize, usize); 8] = [
    (7, 12),
    (12, 7),
    (6, 12),
    (12, 6),
    (4, 4),
    (3, 4),
    (3, 3),
    (2, 3),
];

/// Default grid rows (the report's layout).
pub const DEFAULT_ROWS: usize = 7;
/// Default grid columns.
pub const DEFAULT_COLS: usize = 12;
/// Default coolant and ambient temperature of the grid \[degC\].
pub const GRID_DEFAULT_C: f64 = 20.0;

/// Name of coil `(row, col)`.
pub fn coil_name(row: usize, col: usize) -> String {
    format!("coil_r{row}_c{col}")
}

/// Trace column of coil `(row, col)`'s current \[A\].
pub fn coil_column(row: usize, col: usize) -> String {
    format!("I_r{row}_c{col}_a")
}

/// The supported sizes as text, for messages.
pub fn grid_sizes_text() -> String {
    GRID_SIZES
        .iter()
        .map(|(r, c)| format!("{r}x{c}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Parses an HPPA parameter set name (`fdm-fitted`, `calculated`,
/// `stepwise-fit`, `global-fit`).
pub fn grid_preset(name: &str) -> Result<GridParams> {
    Ok(GridParams::hppa(match name {
        "fdm-fitted" => HppaPreset::FdmFitted,
        "calculated" => HppaPreset::Calculated,
        "stepwise-fit" => HppaPreset::StepwiseFit,
        "global-fit" => HppaPreset::GlobalFit,
        other => bail!(
            "unknown HPPA parameter set `{other}`: one of fdm-fitted, calculated, stepwise-fit, global-fit"
        ),
    }))
}

/// The HPPA grid of `rows x cols` coils with `params` as a model file (see
/// the module docs); refuses sizes outside [`GRID_SIZES`].
pub fn grid_file(rows: usize, cols: usize, params: &GridParams) -> Result<ModelFile> {
    macro_rules! dispatch {
        ($(($r:literal, $c:literal)),*) => {
            match (rows, cols) {
                $(($r, $c) => grid_file_sized::<$r, $c, { $r * $c }>(params),)*
                _ => bail!(
                    "HPPA grid size {rows}x{cols} is not built into this tool: use --rows R --cols C with one of {} (rows x cols)",
                    grid_sizes_text()
                ),
            }
        };
    }
    dispatch!(
        (7, 12),
        (12, 7),
        (6, 12),
        (12, 6),
        (4, 4),
        (3, 4),
        (3, 3),
        (2, 3)
    )
}

fn grid_net<const R: usize, const C: usize, const N: usize>(
    params: GridParams,
) -> Result<coil_thermal::Network<N, 2, N>> {
    let grid = CoilGrid::<f64, R, C>::new(&GridConfig::hppa(params))
        .map_err(|e| anyhow::anyhow!("HPPA grid {R}x{C}: {e}"))?;
    grid.to_network::<N>()
        .map_err(|e| anyhow::anyhow!("HPPA grid {R}x{C}: {e}"))
}

fn grid_file_sized<const R: usize, const C: usize, const N: usize>(
    params: &GridParams,
) -> Result<ModelFile> {
    // Which links go through Rx and which through Ry: the same grid with a
    // unit Rx and a negligible Gy (and the reverse) counts them.
    let big = 1e12;
    let x_only = grid_net::<R, C, N>(GridParams::between_coils(1.0, big, 1.0, 68.7))?;
    let y_only = grid_net::<R, C, N>(GridParams::between_coils(big, 1.0, 1.0, 68.7))?;
    let net = grid_net::<R, C, N>(*params)?;
    let rx = params.rx_between_coils_k_per_w();
    let ry = params.ry_between_coils_k_per_w();
    let rz = params.rz_k_per_w();
    let names: Vec<String> = (0..N).map(|i| coil_name(i / C, i % C)).collect();
    let link = |kind: &str, a: &str, b: &str, r: f64, count: f64| ConductanceSpec {
        name: Some(format!("{kind}:{a}-{b}")),
        between: [a.to_string(), b.to_string()],
        g_w_per_k: None,
        r_k_per_w: Some(r),
        h_w_per_m2k: None,
        area_m2: None,
        factor: (count != 1.0).then_some(count),
        speed: None,
    };
    let mut conductances = Vec::new();
    for a in 0..N {
        for b in (a + 1)..N {
            if net.conductance_w_per_k(a, b) != 0.0 {
                // With unit R the other net's conductance is the link's
                // share of `1/R` (1 for Rx; 1/2 for each herringbone contact,
                // which shares its side's Ry with one other).
                let share_x = x_only.conductance_w_per_k(a, b);
                let (kind, r, share) = if share_x > 0.25 {
                    ("gx", rx, share_x)
                } else {
                    ("gy", ry, y_only.conductance_w_per_k(a, b))
                };
                conductances.push(link(kind, &names[a], &names[b], r, share));
            }
        }
        let nx = x_only.boundary_conductance_w_per_k(a, 1);
        let ny = y_only.boundary_conductance_w_per_k(a, 1);
        if nx > 0.0 {
            conductances.push(link("gx", &names[a], "ambient", rx, nx));
        }
        if ny > 0.0 {
            conductances.push(link("gy", &names[a], "ambient", ry, ny));
        }
        conductances.push(link("gz", &names[a], "coolant", rz, 1.0));
    }
    let resistance = GridConfig::hppa(*params).resistance;
    let sources = (0..N)
        .map(|i| SourceSpec {
            name: None,
            node: names[i].clone(),
            input: Some(names[i].clone()),
            column: Some(coil_column(i / C, i % C)),
            r0_ohm: None,
            alpha_per_k: None,
            t_ref_c: None,
            slope_ohm_per_k: Some(resistance.slope_ohm_per_k),
            r_at_0c_ohm: Some(resistance.r_at_0c_ohm),
            scale: None,
            scale_per_kj: None,
            speed: None,
            drive: None,
            supply_v: None,
            supply_column: None,
        })
        .collect();
    let boundary = |name: &str| BoundarySpec {
        name: name.to_string(),
        column: None,
        value_c: Some(GRID_DEFAULT_C),
    };
    Ok(ModelFile {
        name: Some(format!("hppa-{R}x{C}")),
        description: Some(format!(
            "HPPA coil grid, {R} rows x {C} columns (coil_thermal::grid, herringbone stencil, ambient padding); \
             r_k_per_w of gx/gy links between two coils (the report's Table 7 convention), \
             each herringbone cross-row contact with factor 0.5 (a side's Ry shared by its two contacts)"
        )),
        max_step_ratio: None,
        input_hold: None,
        nodes: names
            .iter()
            .map(|n| NodeSpec {
                name: n.clone(),
                capacity_j_per_k: params.capacity_j_per_k(),
                critical_c: Some(HPPA_CRITICAL_C),
                lags: None,
                time_constant_s: None,
            })
            .collect(),
        boundaries: vec![boundary("coolant"), boundary("ambient")],
        conductances,
        sources,
        conductors: Vec::new(),
        fixed_powers: Vec::new(),
        speed_losses: Vec::new(),
        losses: Vec::new(),
        initial: InitialSpec::default(),
        observer: None,
    })
}

/// The grid parameter names of [`access_grid_param`].
pub const GRID_PARAMS: [&str; 4] = ["rx_k_per_w", "ry_k_per_w", "rz_k_per_w", "capacity_j_per_k"];

/// Reads (`set = None`) or writes a grid parameter `grid.<field>` of a grid
/// model file: `rx_k_per_w`, `ry_k_per_w` (between two coils \[K/W\]),
/// `rz_k_per_w` \[K/W\], `capacity_j_per_k` \[J/K\]. Returns the value before
/// the write.
pub fn access_grid_param(file: &mut ModelFile, field: &str, set: Option<f64>) -> Result<f64> {
    let prefix = match field {
        "rx_k_per_w" => "gx:",
        "ry_k_per_w" => "gy:",
        "rz_k_per_w" => "gz:",
        "capacity_j_per_k" => {
            let old = file
                .nodes
                .first()
                .map(|n| n.capacity_j_per_k)
                .context("the model has no nodes")?;
            if let Some(v) = set {
                for n in &mut file.nodes {
                    n.capacity_j_per_k = v;
                }
            }
            return Ok(old);
        }
        other => bail!(
            "unknown grid parameter `grid.{other}` (grid.{})",
            GRID_PARAMS.join(", grid.")
        ),
    };
    let mut old = None;
    for c in &mut file.conductances {
        if c.name.as_deref().is_some_and(|n| n.starts_with(prefix)) {
            old = old.or(c.r_k_per_w);
            if let Some(v) = set {
                c.r_k_per_w = Some(v);
            }
        }
    }
    old.with_context(|| {
        format!("`grid.{field}` applies to the HPPA grid (--model hppa): this model has no `{prefix}` conductances")
    })
}

/// Which coils a calibration pattern drives on a `rows x cols` grid: all,
/// the middle row `rows / 2`, the middle line `(cols - 1) / 2`, or the centre
/// coil (both), as the committed 7 x 12 traces (row 3, line 5).
pub fn pattern_on(pattern: &str, rows: usize, cols: usize, row: usize, col: usize) -> bool {
    let (mr, mc) = (rows / 2, (cols.max(1) - 1) / 2);
    match pattern {
        "all" => true,
        "row" => row == mr,
        "line" => col == mc,
        _ => row == mr && col == mc,
    }
}

/// Largest sub-step of [`OmnimagnetPlant`] \[s\] (the model's RK4 is stable
/// to about 0.5 s).
pub const OMNIMAGNET_MAX_STEP_S: f64 = 0.25;

/// Omnimagnet current input names (solenoid 1 inner .. 3 outer).
pub const OMNIMAGNET_INPUTS: [&str; SOLENOIDS] = ["current_1", "current_2", "current_3"];
/// Default trace columns of the Omnimagnet currents \[A\].
pub const OMNIMAGNET_COLUMNS: [&str; SOLENOIDS] = ["I1_a", "I2_a", "I3_a"];
/// Default Omnimagnet ambient \[degC\]: the paper's experiments' (the
/// all-three run at 3.8 A from 22 degC reached 115 degC within 2 h).
pub const OMNIMAGNET_DEFAULT_AMBIENT_C: f64 = 22.0;

/// The Omnimagnet's channels and names.
pub fn omnimagnet_info() -> PlantInfo {
    PlantInfo {
        name: "omnimagnet".into(),
        nodes: NODE_NAMES.iter().map(|s| s.to_string()).collect(),
        critical_c: CRITICAL_TEMPS_C.to_vec(),
        inputs: OMNIMAGNET_INPUTS
            .iter()
            .zip(OMNIMAGNET_COLUMNS)
            .map(|(n, c)| Channel {
                name: n.to_string(),
                column: c.to_string(),
                default_value: None,
            })
            .collect(),
        boundaries: vec![Channel {
            name: "ambient".into(),
            column: "ambient".into(),
            default_value: Some(OMNIMAGNET_DEFAULT_AMBIENT_C),
        }],
        signals: Vec::new(),
        initial: InitialSpec::default(),
    }
}

/// The paper's Omnimagnet, nonlinear, stepped by its own RK4.
#[derive(Debug, Clone)]
pub struct OmnimagnetPlant {
    model: Omnimagnet,
    info: PlantInfo,
    temps: [f64; NODES],
}

impl Default for OmnimagnetPlant {
    fn default() -> Self {
        Self::new(Omnimagnet::PAPER)
    }
}

impl OmnimagnetPlant {
    /// Wraps a validated model.
    pub fn new(model: Omnimagnet) -> Self {
        Self {
            model,
            info: omnimagnet_info(),
            temps: [OMNIMAGNET_DEFAULT_AMBIENT_C; NODES],
        }
    }
}

impl Plant for OmnimagnetPlant {
    fn info(&self) -> &PlantInfo {
        &self.info
    }
    fn reset(&mut self, temps_c: &[f64]) {
        self.temps.copy_from_slice(temps_c);
    }
    fn step(&mut self, dt_s: f64, currents_a: &[f64], boundary_c: &[f64], _signals: &[f64]) {
        let n = (dt_s / OMNIMAGNET_MAX_STEP_S).ceil().max(1.0) as usize;
        let h = dt_s / n as f64;
        let currents = [currents_a[0], currents_a[1], currents_a[2]];
        for _ in 0..n {
            self.model
                .step_rk4(&mut self.temps, &currents, boundary_c[0], h);
        }
    }
    fn temps_c(&self) -> &[f64] {
        &self.temps
    }
    fn steps_for(&self, dt_s: f64) -> f64 {
        (dt_s / OMNIMAGNET_MAX_STEP_S).ceil().max(1.0)
    }
}

/// The Omnimagnet's network linearised at every node at `op_c` \[degC\] and
/// the ambient `op_c`, as a model file (critical temperatures included).
pub fn omnimagnet_file(op_c: f64) -> Result<ModelFile> {
    let net = Omnimagnet::PAPER
        .network(&[op_c; NODES], op_c)
        .map_err(|e| anyhow::anyhow!("omnimagnet: {e}"))?;
    let names: [String; NODES] = core::array::from_fn(|i| NODE_NAMES[i].to_string());
    let inputs: [String; SOLENOIDS] = core::array::from_fn(|i| OMNIMAGNET_INPUTS[i].to_string());
    let mut file = ModelFile::from_network(&net, &names, &["ambient".to_string()], &inputs);
    file.name = Some("omnimagnet".into());
    file.description = Some(format!(
        "Omnimagnet 16-node model (coil_thermal::omnimagnet::PAPER) linearised at {op_c} degC"
    ));
    for (node, c) in file.nodes.iter_mut().zip(CRITICAL_TEMPS_C) {
        node.critical_c = c;
    }
    for (s, col) in file.sources.iter_mut().zip(OMNIMAGNET_COLUMNS) {
        s.column = Some(col.to_string());
    }
    file.boundaries[0].value_c = Some(op_c);
    Ok(file)
}

/// Parses an Omnimagnet preset name: `all-three`, `solenoid-1`,
/// `solenoids-2-3`, `cooling`, `rotating-dipole`.
pub fn omnimagnet_preset(name: &str) -> Result<Preset> {
    Ok(match name {
        "all-three" => Preset::ALL_THREE,
        "solenoid-1" => Preset::SOLENOID_1,
        "solenoids-2-3" => Preset::SOLENOIDS_2_AND_3,
        "cooling" => Preset::PASSIVE_COOLING,
        "rotating-dipole" => Preset::ROTATING_DIPOLE,
        other => bail!(
            "unknown Omnimagnet preset `{other}`: one of all-three, solenoid-1, solenoids-2-3, cooling, rotating-dipole"
        ),
    })
}
