//! The firmware examples' golden outputs (`examples/*.expected`, which CI
//! compares with what the firmware prints under QEMU) recomputed from
//! nothing the firmware runs: the grid lines against the dense f64 RK4
//! reference ([`GridReference`]), the derating rule by hand and the
//! time-to-limit bound of `coil_thermal::observer::grid` re-derived in f64
//! from the raw parameters. A golden regenerated from wrong code would
//! otherwise pass CI by construction.
//!
//! Only the grid lines are checked; the Omnimagnet lines follow its model,
//! which has its own tests against the nonlinear reference.

use coil_thermal::grid::Link;
use coil_thermal::protect::derating::HPPA_CRITICAL_C;
use coil_thermal::Stencil;
use coil_thermal_host::grid_reference::{GridReference, ReferenceParams};

const ROWS: usize = 7;
const COLS: usize = 12;
const N: usize = ROWS * COLS;

fn golden(name: &str) -> String {
    let path = format!("{}/../examples/{name}.expected", env!("CARGO_MANIFEST_DIR"));
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"))
}

/// The text of `line` between `start` and the next `end`.
fn between<'a>(line: &'a str, start: &str, end: &str) -> &'a str {
    let from = line
        .find(start)
        .unwrap_or_else(|| panic!("no {start:?} in {line:?}"))
        + start.len();
    let len = line[from..]
        .find(end)
        .unwrap_or_else(|| panic!("no {end:?} after {start:?} in {line:?}"));
    &line[from..from + len]
}

fn number(text: &str) -> f64 {
    text.trim()
        .parse()
        .unwrap_or_else(|e| panic!("{text:?}: {e}"))
}

/// `(row, col)` from `"(3, 5)"`.
fn coil(text: &str) -> (usize, usize) {
    let inner = text.trim().trim_start_matches('(').trim_end_matches(')');
    let (r, c) = inner.split_once(',').expect("(row, col)");
    (number(r) as usize, number(c) as usize)
}

fn reference() -> GridReference {
    GridReference::assemble(
        ROWS,
        COLS,
        &Stencil::HPPA_HERRINGBONE,
        &ReferenceParams::HPPA_FDM,
    )
}

/// The HPPA alarm limit (derating-rule.md): `T_amb + (T_crit - T_amb)`
/// times 0.875 (magnet plate) x 0.9 (model error) x 0.9 (unknown
/// conditions) x 0.8 (safety) \[degC\].
fn hppa_alarm_limit_c(ambient_c: f64) -> f64 {
    ambient_c + (HPPA_CRITICAL_C - ambient_c) * (0.875 * 0.9 * 0.9 * 0.8)
}

/// Each coil's conductance to the other coils and to the ambient padding
/// \[W/K\]: the herringbone links of `hppa-coil-grid.md`, `1 / Rx` in the
/// row, a side's `1 / Ry` shared by its cross-row contacts.
fn link_conductances(p: &ReferenceParams) -> (Vec<f64>, Vec<f64>) {
    let stencil = Stencil::HPPA_HERRINGBONE;
    let (mut neighbours, mut padding) = (vec![0.0; N], vec![0.0; N]);
    for r in 0..ROWS {
        let matrix = if r % 2 == 0 {
            &stencil.even
        } else {
            &stencil.odd
        };
        for c in 0..COLS {
            for (a, side) in matrix.iter().enumerate() {
                let contacts = side.iter().filter(|l| **l == Link::Y).count() as f64;
                for (b, link) in side.iter().enumerate() {
                    let g = match link {
                        Link::None => continue,
                        Link::X => 1.0 / p.rx_k_per_w,
                        Link::Y => 1.0 / (p.ry_k_per_w * contacts),
                    };
                    let (rr, cc) = (r + a, c + b);
                    if (1..=ROWS).contains(&rr) && (1..=COLS).contains(&cc) {
                        neighbours[r * COLS + c] += g;
                    } else {
                        padding[r * COLS + c] += g;
                    }
                }
            }
        }
    }
    (neighbours, padding)
}

/// The time-to-limit bound of `coil_thermal::observer::grid`'s module docs
/// for coil `coil`, in f64 from the raw parameters: powers
/// `p_i = R(max(T_i, L)) I_i^2` at the alarm limit `L`, the bound
/// `U = max(max T_i, max (p_i + G_z T_c + G_a,i T_a) / (G_z + G_a,i))`, and
/// the coil's crossing of `target_c` with every neighbour at `U`.
fn bound_time_to_limit_s(
    temps_c: &[f64],
    currents_a: &[f64],
    boundary_c: f64,
    limit_c: f64,
    target_c: f64,
    coil: usize,
) -> Option<f64> {
    let p = ReferenceParams::HPPA_FDM;
    let (neighbours, padding) = link_conductances(&p);
    let base = 1.0 / p.rz_k_per_w;
    let inflow = |i: usize| {
        let r_ohm = p.r_at_0c_ohm + p.slope_ohm_per_k * temps_c[i].max(limit_c);
        r_ohm * currents_a[i].powi(2) + (base + padding[i]) * boundary_c
    };
    let bound_c = (0..N)
        .map(|i| inflow(i) / (base + padding[i]))
        .chain(temps_c.iter().copied())
        .fold(f64::NEG_INFINITY, f64::max);
    let total = neighbours[coil] + base + padding[coil];
    let steady_c = (inflow(coil) + neighbours[coil] * bound_c) / total;
    let t = temps_c[coil];
    (steady_c > target_c)
        .then(|| p.capacity_j_per_k / total * ((steady_c - t) / (steady_c - target_c)).ln())
}

/// The first time \[s\] coil `coil` reaches `limit_c` by RK4 at 0.05 s.
fn true_crossing_s(
    reference: &GridReference,
    temps_c: &[f64],
    currents_a: &[f64],
    boundary_c: f64,
    limit_c: f64,
    coil: usize,
) -> f64 {
    let (h, mut t, mut now) = (0.05, temps_c.to_vec(), 0.0);
    loop {
        let before = t[coil];
        reference.integrate(&mut t, currents_a, boundary_c, boundary_c, h, h);
        if t[coil] >= limit_c {
            return now + h * (limit_c - before) / (t[coil] - before);
        }
        now += h;
        assert!(now < 3_600.0, "coil {coil} never reaches {limit_c} degC");
    }
}

/// `observer_m4`: the 84-coil grid observer, coil (3, 5) at 2 A and row 1
/// at 1 A, coolant and ambient 22 degC, 20 001 steps of 1 ms (the grid
/// updated every 20), then the protection pass finished.
#[test]
fn observer_m4_grid_line_matches_the_f64_reference() {
    let text = golden("observer_m4");
    let line = text
        .lines()
        .find(|l| l.starts_with("grid:"))
        .expect("a grid line in observer_m4.expected");
    let steps = number(between(line, "grid: ", " steps"));
    let hottest = coil(between(line, "hottest coil ", " at"));
    let hottest_c = number(between(line, ") at ", " degC"));
    let limit_a = number(between(line, "limit ", " A"));
    let printed_s = number(between(line, "time to limit Some(", ") s"));
    let predictive = match line.split("predictive alarm ").nth(1).map(str::trim) {
        Some("true") => true,
        Some("false") => false,
        other => panic!("predictive alarm {other:?}"),
    };

    let ambient_c = 22.0;
    let mut currents = vec![0.0; N];
    currents[3 * COLS + 5] = 2.0;
    currents[COLS..2 * COLS].fill(1.0);
    // The temperatures the protection saw are those of the last update,
    // at step 20 000.
    assert_eq!(steps, 20_001.0);
    let reference = reference();
    let mut temps = vec![ambient_c; N];
    reference.integrate(&mut temps, &currents, ambient_c, ambient_c, 20.0, 0.05);
    let (hot, hot_c) =
        temps.iter().enumerate().fold(
            (0, f64::MIN),
            |m, (i, t)| if *t > m.1 { (i, *t) } else { m },
        );
    let limit_c = hppa_alarm_limit_c(ambient_c);
    // The observer's default model-uncertainty margin `f` protects the
    // bound `T + f (T - T_ref)` (`protect::margin`), which reaches the limit
    // when the mean reaches `T_ref + (L - T_ref) / (1 + f)`; T_ref is the
    // colder of coolant and ambient.
    let f = coil_thermal::observer::grid::DEFAULT_MARGIN.rise_fraction;
    let target_c = ambient_c + (limit_c - ambient_c) / (1.0 + f);
    let bound_s = bound_time_to_limit_s(&temps, &currents, ambient_c, limit_c, target_c, hot)
        .expect("the 2 A coil's bound crosses");
    let truth_s = true_crossing_s(&reference, &temps, &currents, ambient_c, target_c, hot);
    println!(
        "observer_m4: hottest coil {hottest:?} at {hottest_c} degC (reference ({}, {}) at {hot_c:.6}), \
         time to limit {printed_s} s (bound in f64 {bound_s:.4} s, true crossing {truth_s:.2} s, \
         limit {limit_c:.3} degC, mean limit {target_c:.3} degC)",
        hot / COLS,
        hot % COLS
    );
    assert_eq!(hottest, (hot / COLS, hot % COLS));
    // The firmware's grid is explicit Euler at its 20 ms update in f32, a
    // 6.3 K rise in 20 s: a few mK from RK4 (0.4 mK on the host).
    assert!(
        (hottest_c - hot_c).abs() < 0.01,
        "hottest {hottest_c} degC, reference {hot_c} degC"
    );
    // The bound's inputs differ by those mK: dt/dT = tau / (y_ss - T) =
    // 122 s / 152 K = 0.8 s/K here, so 8 ms at the 10 mK allowed above
    // (0.4 mK and 0.3 ms measured against the library on the host), plus
    // f32 and the library's ln (a few ulps). Powers at R(T) instead of
    // R(L) print 21.19 s against 17.79 s.
    assert!(
        (printed_s - bound_s).abs() < 0.01,
        "time to limit {printed_s} s, bound in f64 {bound_s} s"
    );
    // And the bound is what it claims: no later than the truth.
    assert!(printed_s <= truth_s, "{printed_s} s, truth {truth_s} s");
    // Below 60 s, the alarm's default horizon: predictive.
    assert_eq!(predictive, printed_s < 60.0);
    // 28.3 degC (its bound with the margin 32.3 degC) is far below the
    // limiter's taper (10 K under the limit): full current.
    assert_eq!(limit_a, 3.0);
}

/// `grid_qemu`: the bare grid, coil (3, 5) at 2 A for 60 s from 20 degC
/// (its three hottest coils), then an adiabatic constant-R grid at 0.7 A.
#[test]
fn grid_qemu_lines_match_the_f64_reference() {
    let text = golden("grid_qemu");
    let reference = reference();
    let mut currents = vec![0.0; N];
    currents[3 * COLS + 5] = 2.0;
    let mut temps = vec![20.0; N];
    reference.integrate(&mut temps, &currents, 20.0, 20.0, 60.0, 0.05);
    let mut checked = 0;
    for line in text.lines().filter(|l| l.starts_with("60 s at 2 A:")) {
        let (r, c) = coil(between(line, "coil ", " at"));
        let printed_c = number(between(line, ") at ", " degC"));
        let want_c = temps[r * COLS + c];
        println!("grid_qemu: coil ({r}, {c}) at {printed_c} degC, reference {want_c:.6} degC");
        // Euler at the 10 ms update, f32: 16 K of rise in 60 s.
        assert!(
            (printed_c - want_c).abs() < 0.01,
            "coil ({r}, {c}): {printed_c} degC, reference {want_c} degC"
        );
        checked += 1;
    }
    assert_eq!(checked, 3);
    let line = text
        .lines()
        .find(|l| l.starts_with("all on, adiabatic:"))
        .expect("the adiabatic line");
    let printed_c = number(between(line, "adiabatic: ", " degC"));
    // Every coil equally hot: no lateral flow, so P Rz above the coolant.
    let closed_form_c = 20.0 + 5.69 * 0.7 * 0.7 * ReferenceParams::HPPA_FDM.rz_k_per_w;
    println!("grid_qemu: all on, adiabatic {printed_c} degC, P Rz {closed_form_c:.6} degC");
    assert!((printed_c - closed_form_c).abs() < 1e-4);
}
