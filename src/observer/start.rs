//! Safe from the first tick: what a filtered observer assumes when it
//! starts without a trusted history, and how a restore whose off time is
//! unknown finds it from the sensors.
//!
//! # The start without history
//!
//! After a reset with no snapshot (the first boot, a refused snapshot, a
//! product that keeps none) the sensors say where the measured nodes are,
//! and nothing says where the others are: a winding may sit at the ambient
//! (a cold motor) or near its limit (a reset at the hottest moment of a
//! run, the housing still cool). Starting them at the ambient is what let a
//! warm motor's winding pass its limit (its healthy readings then looked
//! impossible to the filter and were refused). The start here says what is
//! known and what is not:
//!
//! * **mean**: every measured node at its reading, every other node no
//!   cooler than the hottest reading or the ambient
//!   ([`conservative_start`](super::snapshot::conservative_start));
//! * **covariance**: the steady one, widened on every node no sensor read
//!   at the start by a standard deviation that puts each limited element's
//!   protective upper bound [`START_BELOW_LIMIT_K`] below its alarm limit
//!   ([`start_sigma_k`]): the hottest the element can be if the protection
//!   held before the reset. An unlimited node no sensor reads gets the
//!   largest of those (it may be as hot as any);
//! * **the filter holds that covariance**: the time-varying filter runs
//!   from it (the covariance propagated every step, a Joseph update per
//!   correction) until every variance is within [`SETTLED_FRACTION`] of the
//!   steady posterior's, then the steady gain takes over. The gate judges
//!   each innovation against the covariance held, so a healthy reading is
//!   never refused because the start was wrong;
//! * **the upper bound follows the covariance held**: `k` times the held
//!   standard deviation where the steady one is wider ([`bound_extra_k`]).
//!   So the limiter starts in its taper band (at the default 10 K band and
//!   a 1 K start, `sqrt(1/10)`: 32 % of the hardware current) and opens as
//!   the sensors teach the filter: no latched shutdown, no assumed cold
//!   winding;
//! * **the limiter acts on the doubt, the alarm on the evidence**: while
//!   the wider covariance is held, the alarm (warning and latched
//!   shutdown) judges the steady bound, the estimate plus the steady
//!   `k sigma` and margin, and the limiter and the published `upper_c`
//!   the widened one. The widened bound of a hot start rises past the
//!   limit as the filter's mean climbs faster than its deviation shrinks
//!   (a reset at the hottest point of a three-phase motor's run latched a
//!   shutdown 21 s in, the winding 0.9 K under its limit): a doubt that
//!   the limiter already answers with no current. A device really above
//!   its limit at the start is shut down as soon as the mean shows it.
//!
//! A device whose heat sources all sit at nodes with a value at the start
//! (read, or started conservatively where their sensors are silent: the
//! Omnimagnet's three solenoids, two thermocouples each) starts its other
//! nodes at the steady state of its network with those held
//! ([`held_steady_state_c`], with the conductances at the start's
//! temperatures), each between the ambient (or the coolest reading) and
//! the hottest reading: with no source among them a steady state puts
//! them there, and after a run near its steady state they are close to it
//! (every Omnimagnet insulation and frame within 0.7 K at the hottest
//! point of a 3 h run; 10 min into the cooling the frames lag, up to
//! 2.6 K warmer than it; the core, hours slow, is the exception the
//! variance covers). With the covariance held wide the mean need not err
//! hot (the bound does), and a mean at the hottest reading puts every
//! unread neighbour of an insulation hotter than it is (the Omnimagnet's
//! frames 5 to 14 K), whose heat then raises the insulation's estimate by
//! a kelvin within a second: at the hottest point, where the insulation's
//! bound sits at its limit, that alone latched the shutdown.
//!
//! Where the hottest reading is already above the level at which a limited
//! element's upper bound is [`START_BELOW_LIMIT_K`] below its alarm limit
//! (a measured heat source hotter than the insulation it protects, as the
//! Omnimagnet's solenoids and their covers: the solenoids run some kelvin
//! above the cover's limit at the protected steady state), that element
//! starts at that level ([`cap_unread_c`]): if the protection held before
//! the reset it was no hotter than its limit, so the bound covers it
//! within [`START_BELOW_LIMIT_K`], and a start at the hottest reading
//! would put its bound above the limit and latch the shutdown.
//!
//! # A covariance per correction period, in slices
//!
//! An observer whose tick cannot afford the covariance predict of every
//! model step (the Omnimagnet's 19 states: about 8 400 multiply-adds per
//! step against a 0.1 ms tick) holds the start's covariance once per
//! correction period instead, in slices spread over the light ticks
//! between corrections (`held::HeldCovariance`, crate-private; `X`
//! states, the first `T` with dynamics, `K` measured by `P` sensors): the
//! readings fused against the period's prior are kept as information per
//! measured state (the batch update of any number of readings), and the
//! next prior is the steady solution plus the start's excess carried by
//! the period's transition, `F (P+ - P_ss) F^T + M` (no `Q_k` needed: `M`
//! carries it), in slices of at most `(T + 1) X + K X` multiply-adds. The
//! slices after a correction or a new prior also make what the next
//! correction needs, the gain of all the sensors, `S` and `M H^T`, so the
//! correction is the steady filter's own code on them
//! ([`crate::filter::update_steady`]) and costs what a steady one does.
//! The period's transition `F` is one every such observer already keeps:
//! its unfused shadow steps one correction period.
//!
//! # The restore with an unknown off time
//!
//! A snapshot says where the device was when it was saved; without a clock
//! the off time is only known to lie between 0 and the snapshot's age.
//! Every off time in that range gives a state (the exact zero-current
//! cooling of the saved one), and the readings at the restore say which
//! are possible: [`earliest_off_time_s`] finds the *shortest* off time
//! that cools some sensor's node to its reading (plus a tolerance; every
//! sensor's node is then set at its reading, [`at_readings`]), the least
//! cooling the readings allow, so the unmeasured nodes err hot and the
//! measured ones agree with their sensors from the first correction (no
//! healthy reading refused, no "colder than the physics").

mod held;

pub(crate) use held::{
    period_slices, slices_per_tick, HeldCovariance, HeldLayout, PeriodTransition, Propagation,
};

use nalgebra::{SMatrix, SVector};

/// How far below its alarm limit the start puts the protective upper bound
/// of a limited element no sensor reads \[K\]: below the shutdown level
/// (the start never latches), inside the limiter's taper band (the current
/// is limited until the sensors say more).
pub const START_BELOW_LIMIT_K: f32 = 1.0;

/// The start's warm-up ends when every variance of the covariance it holds
/// is within this share of the steady posterior's (dimensionless).
pub const SETTLED_FRACTION: f32 = 0.05;

/// A bound the start's covariance widens by less than this \[K\] has
/// forgotten the start: once every solenoid's and insulation's bound has,
/// an observer that held its unfused shadow on the estimate through the
/// start lets it run free again (the slow states' excess may be held for
/// hours, see [`MAX_START_CORRECTIONS`]).
pub const START_FORGOTTEN_K: f32 = 0.1;

/// The most corrections the start's warm-up runs before the steady gain
/// takes over whatever its covariance: at a 0.5 s correction period, 9 h.
pub const MAX_START_CORRECTIONS: u16 = u16::MAX;

/// Off times [`earliest_off_time_s`] tries on a geometric grid before it
/// refines the first that fits.
const OFF_TIME_GRID: u32 = 32;
/// Bisection steps of that refinement: the bracket shrinks `2^20`-fold.
const OFF_TIME_BISECTIONS: u32 = 20;

/// The standard deviation \[K\] the start gives each node, node by node
/// (one per node, every slice holding one entry per node): `None` for a
/// node a sensor read at the start (it keeps its steady variance), else
/// the one at which its upper bound is [`START_BELOW_LIMIT_K`] below its
/// alarm limit.
///
/// `steady_upper_c` is each node's upper bound at the start's mean with the
/// steady `k sigma` (whose `sigma` is `steady_sigma_k`), `limits_c` its
/// alarm limit, `limited` whether it has one, `k_sigma` the bound's `k`
/// (at least 1 is used: the spread must be a variance even when the bound
/// takes no `k sigma`). An element already at or above that level keeps
/// its steady deviation.
pub fn start_sigma_k<'a>(
    read: &'a [bool],
    steady_upper_c: &'a [f32],
    limits_c: &'a [f32],
    limited: &'a [bool],
    steady_sigma_k: &'a [f32],
    k_sigma: f32,
) -> impl Iterator<Item = Option<f32>> + 'a {
    let k = if k_sigma >= 1.0 { k_sigma } else { 1.0 };
    let gap_k = move |(upper, limit): (&f32, &f32)| {
        let gap = limit - START_BELOW_LIMIT_K - upper;
        if gap.is_finite() && gap > 0.0 {
            gap
        } else {
            0.0
        }
    };
    let gaps = move || steady_upper_c.iter().zip(limits_c).map(gap_k);
    let widest_k = gaps()
        .zip(limited.iter().zip(read))
        .filter(|(_, (limited, read))| **limited && !**read)
        .fold(0.0f32, |a, (gap, _)| a.max(gap));
    gaps()
        .zip(read.iter().zip(limited).zip(steady_sigma_k))
        .map(move |(gap, ((read, limited), sigma))| {
            let gap = if *limited { gap } else { widest_k };
            (!*read).then_some(sigma + gap / k)
        })
}

/// Lowers every limited element no sensor read at the start (`read`
/// false, `limited` true) that starts hotter than `ceiling_c` \[degC\] to
/// it: `ceiling_c` is the mean at which its steady upper bound is
/// [`START_BELOW_LIMIT_K`] below its alarm limit (see the module docs).
/// A NaN ceiling changes nothing.
pub fn cap_unread_c<const N: usize>(
    temps_c: &mut [f32; N],
    read: &[bool; N],
    limited: &[bool; N],
    ceiling_c: &[f32; N],
) {
    for (((t, read), limited), ceiling) in temps_c.iter_mut().zip(read).zip(limited).zip(ceiling_c)
    {
        if *limited && !*read && *t > *ceiling {
            *t = *ceiling;
        }
    }
}

/// The steady state \[degC\] of a network of conductances
/// (`pair_w_per_k[i][j]` \[W/K\] between nodes `i` and `j`, symmetric,
/// `boundary_w_per_k[i]` \[W/K\] from node `i` to a boundary at
/// `boundary_c` \[degC\]) with every node that has a value in `held_c`
/// \[degC\] held there and no heat source at the others: for a network
/// whose heat sources are all held, where its other nodes settle whatever
/// the powers (see the module docs). An `N x N` solve in `f64` (at the
/// start, not in a tick); `None` if the system is singular or the result
/// not finite.
pub fn held_steady_state_c<const N: usize>(
    pair_w_per_k: &[[f64; N]; N],
    boundary_w_per_k: &[f64; N],
    boundary_c: f64,
    held_c: &[Option<f64>; N],
) -> Option<[f64; N]> {
    let mut a = SMatrix::<f64, N, N>::zeros();
    let mut b = SVector::<f64, N>::zeros();
    for (i, held) in held_c.iter().enumerate() {
        match held {
            Some(t) => {
                a[(i, i)] = 1.0;
                b[i] = *t;
            }
            None => {
                // sum_j g_ij (T_j - T_i) + g_b (T_b - T_i) = 0.
                let g_b = boundary_w_per_k[i];
                let mut diagonal = -g_b;
                for (j, g) in pair_w_per_k[i].iter().enumerate() {
                    if j != i {
                        a[(i, j)] = *g;
                        diagonal -= *g;
                    }
                }
                a[(i, i)] = diagonal;
                b[i] = -g_b * boundary_c;
            }
        }
    }
    let x = solve(a, b)?;
    Some(core::array::from_fn(|i| x[i]))
}

/// `a x = b` by Gaussian elimination with partial pivoting; `None` for a
/// (numerically) singular `a`.
fn solve<const N: usize>(
    mut a: SMatrix<f64, N, N>,
    mut b: SVector<f64, N>,
) -> Option<SVector<f64, N>> {
    let scale = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    for col in 0..N {
        let pivot = (col..N).max_by(|i, j| a[(*i, col)].abs().total_cmp(&a[(*j, col)].abs()))?;
        let size = a[(pivot, col)].abs();
        if size.is_nan() || size <= 1e-12 * scale {
            return None;
        }
        a.swap_rows(col, pivot);
        b.swap_rows(col, pivot);
        for row in col + 1..N {
            let f = a[(row, col)] / a[(col, col)];
            for k in col..N {
                a[(row, k)] -= f * a[(col, k)];
            }
            b[row] -= f * b[col];
        }
    }
    let mut x = SVector::<f64, N>::zeros();
    for row in (0..N).rev() {
        let mut v = b[row];
        for k in row + 1..N {
            v -= a[(row, k)] * x[k];
        }
        x[row] = v / a[(row, row)];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// The upper bound's widening while a covariance wider than the steady one
/// is held \[K\]: `k (sqrt(var) - sigma_steady)` where positive, else 0.
pub fn bound_extra_k(variance_k2: f32, steady_sigma_k: f32, k_sigma: f32) -> f32 {
    let held = libm::sqrtf(variance_k2);
    let extra = k_sigma * (held - steady_sigma_k);
    if extra.is_finite() && extra > 0.0 {
        extra
    } else {
        0.0
    }
}

/// The start's widening `extra_k` \[K\] of a limited element's upper
/// bound ([`bound_extra_k`] of the covariance held) where the element's
/// steady upper bound is `steady_upper_c` \[degC\] and its alarm limit
/// `limit_c` \[degC\]: no higher than the start's own level,
/// [`START_BELOW_LIMIT_K`] below the limit. The start assumes the
/// protection held before the reset, so its ignorance reaches no higher;
/// only the estimate (the steady bound) can take the bound above it, to
/// the limiter's floor and the alarm. The ignorance held on one element
/// flows into its neighbours' covariance with the first period's
/// propagation (a wire insulation widened to its far limit makes its cover
/// uncertain by kelvins within half a second): without this, that alone
/// would latch the cover's shutdown. A NaN limit keeps `extra_k`.
pub fn capped_extra_k(extra_k: f32, steady_upper_c: f32, limit_c: f32) -> f32 {
    let room_k = limit_c - START_BELOW_LIMIT_K - steady_upper_c;
    if room_k > 0.0 {
        extra_k.min(room_k)
    } else if room_k <= 0.0 {
        0.0
    } else {
        extra_k
    }
}

/// How close a node must come to its sensor's reading for a cooled
/// restore to fit it \[K\]: `k_sigma` (dimensionless) sensor deviations,
/// of the noisiest of the sensors in use (`variances_k2`, \[K^2\], the
/// filter's `R`). 0.75 K at the defaults (3 x 0.25 K).
pub fn restore_tolerance_k(k_sigma: f32, variances_k2: impl IntoIterator<Item = f32>) -> f32 {
    k_sigma
        * variances_k2
            .into_iter()
            .fold(0.0f32, |a, r| a.max(libm::sqrtf(r)))
}

/// The readings \[degC\] a restore may trust: finite, of a sensor in use
/// (`used[j]`), and no colder than `coldest_c` \[degC\] (the coldest
/// boundary the device can have cooled towards) by more than
/// `tolerance_k` \[K\]; the others become `None`. A reading colder than
/// that is no cooling the device can have done: left out (a faulty
/// sensor at the boot).
pub fn restore_readings(
    readings_c: &mut [Option<f32>],
    used: impl IntoIterator<Item = bool>,
    coldest_c: f32,
    tolerance_k: f32,
) {
    // A reading past `used`'s end is of no sensor in use.
    let used = used.into_iter().chain(core::iter::repeat(false));
    for (reading, used) in readings_c.iter_mut().zip(used) {
        *reading = reading.filter(|t| used && t.is_finite() && *t >= coldest_c - tolerance_k);
    }
}

/// The saved state `saved_c` \[degC\] cooled (`cooled(t)`, the state
/// after `t` \[s\] off) by the least off time within `max_off_s` \[s\]
/// the readings allow
/// ([`earliest_off_time_s`]), then every sensor's node at its reading
/// ([`at_readings`]): the cooling that fits one sensor may leave another
/// warmer than its reading (model error, or a node that a hotter
/// neighbour warmed while off), and the sensor is the best knowledge of
/// its node. `readings_c` as [`restore_readings`] leaves them.
pub fn cooled_to_readings<V: AsRef<[f32]> + AsMut<[f32]> + Clone>(
    saved_c: &V,
    cooled: impl Fn(f32) -> V,
    sensor_nodes: &[usize],
    readings_c: &[Option<f32>],
    tolerance_k: f32,
    max_off_s: f32,
) -> V {
    let off_s = earliest_off_time_s(&cooled, sensor_nodes, readings_c, tolerance_k, max_off_s);
    let mut temps_c = if off_s > 0.0 {
        cooled(off_s)
    } else {
        saved_c.clone()
    };
    at_readings(temps_c.as_mut(), sensor_nodes, readings_c);
    temps_c
}

/// Sets every sensor's node in `temps_c` \[degC\] at its reading
/// `readings_c` \[degC\] (`None` or not finite: no reading; two sensors
/// on one node: the hotter, as the start takes it): a restore's cooled
/// state where the sensors read. The cooling that fits one sensor may
/// leave another's node off its reading (model error, or a node that
/// warmed while the device was off: the heat of a hotter neighbour
/// spreading), and the sensor is the best knowledge of its node.
pub fn at_readings(temps_c: &mut [f32], sensor_nodes: &[usize], readings_c: &[Option<f32>]) {
    for (j, (reading, node)) in readings_c.iter().zip(sensor_nodes).enumerate() {
        let Some(t) = reading.filter(|t| t.is_finite()) else {
            continue;
        };
        let hotter_before = readings_c[..j]
            .iter()
            .zip(sensor_nodes)
            .filter(|(r, n)| *n == node && r.is_some_and(f32::is_finite))
            .filter_map(|(r, _)| *r)
            .fold(t, f32::max);
        if let Some(slot) = temps_c.get_mut(*node) {
            *slot = hotter_before;
        }
    }
}

/// The shortest off time \[s\] in `[0, max_off_s]` after which the cooled
/// state (`cooled(t)`, the node temperatures \[degC\] after `t` \[s\] off)
/// puts some sensor with a reading no more than `tolerance_k` \[K\] above
/// it: the least cooling the readings allow (see the module docs; where
/// the sensors disagree, the one that cooled least decides, and the
/// others' nodes are the caller's to set to their readings).
///
/// Only the sensors whose nodes the saved state (`cooled(0)`) puts more
/// than `tolerance_k` above their readings take part: a node can warm
/// while the device is off (a hotter neighbour's heat spreading), and its
/// sensor then fits the uncooled state without saying anything about the
/// time. `0` when no reading is usable or none takes part (nothing says
/// the device cooled); `max_off_s` when none fits (the readings are
/// colder than the device can have cooled: the most cooling there was
/// time for, and the filter does the rest). A geometric grid of
/// 32 off times from 1 s (`OFF_TIME_GRID`), then 20 (`OFF_TIME_BISECTIONS`)
/// bisections between the last that does not fit and the first that does:
/// at most 53 evaluations of `cooled`, at the restore (never in a tick).
pub fn earliest_off_time_s<V: AsRef<[f32]>>(
    cooled: impl Fn(f32) -> V,
    sensor_nodes: &[usize],
    readings_c: &[Option<f32>],
    tolerance_k: f32,
    max_off_s: f32,
) -> f32 {
    if max_off_s.is_nan() || max_off_s <= 0.0 || !max_off_s.is_finite() {
        return 0.0;
    }
    // Only a sensor whose node the saved state puts above its reading says
    // how long the device cooled: one below it (a node that warmed while
    // off, an estimate that was cold) says nothing about the time.
    let saved = cooled(0.0);
    let telling = |j: usize| {
        let reading = readings_c
            .get(j)
            .copied()
            .flatten()
            .filter(|r| r.is_finite())?;
        let model = saved.as_ref().get(*sensor_nodes.get(j)?)?;
        (*model > reading + tolerance_k).then_some(reading)
    };
    if (0..sensor_nodes.len()).all(|j| telling(j).is_none()) {
        return 0.0;
    }
    let fits = |t: f32| {
        let temps = cooled(t);
        let temps = temps.as_ref();
        sensor_nodes
            .iter()
            .enumerate()
            .any(|(j, node)| match (telling(j), temps.get(*node)) {
                (Some(reading), Some(model)) => *model <= reading + tolerance_k,
                _ => false,
            })
    };
    // t_k = max_off_s^(k / GRID): 1 s to max_off_s (a single step below 1 s).
    let ratio = if max_off_s > 1.0 {
        libm::powf(max_off_s, 1.0 / OFF_TIME_GRID as f32)
    } else {
        1.0
    };
    let mut below = 0.0f32;
    let mut above = max_off_s;
    let mut t = if max_off_s > 1.0 { 1.0 } else { max_off_s };
    for _ in 0..=OFF_TIME_GRID {
        if fits(t) {
            above = t;
            break;
        }
        below = t;
        if t >= max_off_s {
            return max_off_s;
        }
        t = (t * ratio).min(max_off_s);
    }
    for _ in 0..OFF_TIME_BISECTIONS {
        let mid = 0.5 * (below + above);
        if fits(mid) {
            above = mid;
        } else {
            below = mid;
        }
    }
    above
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two nodes cooling to 20 degC with time constants 100 s and 1000 s
    /// from 80 and 60 degC.
    fn cooled(t: f32) -> [f32; 2] {
        [
            20.0 + 60.0 * libm::expf(-t / 100.0),
            20.0 + 40.0 * libm::expf(-t / 1000.0),
        ]
    }

    #[test]
    fn the_off_time_found_is_the_shortest_the_readings_allow() {
        // Node 1 read 1000 s after the save: exactly 1000 ln(40 / (r - 20)).
        let truth_s = 600.0f32;
        let reading = cooled(truth_s)[1];
        let t = earliest_off_time_s(cooled, &[1], &[Some(reading)], 0.0, 3600.0);
        assert!((t - truth_s).abs() < 0.5, "{t} s");
        // A tolerance shortens it: the model may then read that much warmer.
        let tol = earliest_off_time_s(cooled, &[1], &[Some(reading)], 0.5, 3600.0);
        let expected = 1000.0 * libm::logf(40.0 / (reading + 0.5 - 20.0));
        assert!((tol - expected).abs() < 0.5, "{tol} s against {expected} s");
        // Two sensors that disagree: the one that cooled least decides.
        let both = earliest_off_time_s(
            cooled,
            &[0, 1],
            &[Some(cooled(900.0)[0]), Some(reading)],
            0.0,
            3600.0,
        );
        assert!((both - truth_s).abs() < 0.5, "{both} s");
        let other = earliest_off_time_s(
            cooled,
            &[0, 1],
            &[Some(cooled(300.0)[0]), Some(reading)],
            0.0,
            3600.0,
        );
        assert!((other - 300.0).abs() < 0.5, "{other} s");
    }

    #[test]
    fn a_node_that_warmed_while_off_does_not_stop_the_cooling() {
        // Node 1 read warmer than saved (it warmed from a neighbour): it
        // fits at once, and says nothing; node 0 decides.
        let truth_s = 300.0f32;
        let t = earliest_off_time_s(
            cooled,
            &[0, 1],
            &[Some(cooled(truth_s)[0]), Some(cooled(0.0)[1] + 2.0)],
            0.0,
            3600.0,
        );
        assert!((t - truth_s).abs() < 0.5, "{t} s");
    }

    #[test]
    fn the_restore_takes_every_sensor_at_its_reading() {
        let mut temps = [50.0f32, 50.0, 50.0];
        at_readings(
            &mut temps,
            &[0, 0, 2, 1],
            &[Some(40.0), Some(42.0), Some(55.0), Some(f32::NAN)],
        );
        assert_eq!(temps, [42.0, 50.0, 55.0]);
    }

    #[test]
    fn no_reading_or_a_saved_state_that_fits_means_no_cooling() {
        assert_eq!(earliest_off_time_s(cooled, &[1], &[None], 0.0, 3600.0), 0.0);
        assert_eq!(
            earliest_off_time_s(cooled, &[1], &[Some(f32::NAN)], 0.0, 3600.0),
            0.0
        );
        assert_eq!(
            earliest_off_time_s(cooled, &[1], &[Some(61.0)], 0.0, 3600.0),
            0.0
        );
        assert_eq!(
            earliest_off_time_s(cooled, &[1], &[Some(30.0)], 0.0, f32::NAN),
            0.0
        );
    }

    #[test]
    fn readings_colder_than_any_cooling_take_the_longest() {
        let t = earliest_off_time_s(cooled, &[1], &[Some(20.0)], 0.0, 600.0);
        assert_eq!(t, 600.0);
    }

    #[test]
    fn the_start_puts_an_unread_element_just_below_its_limit() {
        // Node 0 read; node 1 limited at 100 degC, its steady bound at 40;
        // node 2 unlimited: it takes node 1's spread.
        let sigma: heapless::Vec<Option<f32>, 3> = start_sigma_k(
            &[true, false, false],
            &[30.0, 40.0, 35.0],
            &[100.0, 100.0, 1e9],
            &[true, true, false],
            &[0.1, 0.5, 0.7],
            3.0,
        )
        .collect();
        assert_eq!(sigma.len(), 3);
        assert_eq!(sigma[0], None);
        let s1 = sigma[1].unwrap();
        // Upper bound = steady bound + k (sigma - steady sigma).
        assert!((40.0 + 3.0 * (s1 - 0.5) - (100.0 - START_BELOW_LIMIT_K)).abs() < 1e-4);
        assert!((sigma[2].unwrap() - (0.7 + (s1 - 0.5))).abs() < 1e-5);
        // An element already past that level keeps its steady deviation.
        let hot: heapless::Vec<Option<f32>, 1> =
            start_sigma_k(&[false], &[120.0], &[100.0], &[true], &[0.5], 3.0).collect();
        assert_eq!(hot[..], [Some(0.5)]);
    }

    #[test]
    fn the_held_steady_state_settles_the_free_nodes_between_the_held_ones() {
        // A chain 0 - 1 - 2 - boundary (20 degC), 1 W/K each, node 0 held.
        let pair = [[0.0, 1.0, 0.0], [1.0, 0.0, 1.0], [0.0, 1.0, 0.0]];
        let boundary = [0.0, 0.0, 1.0];
        let temps = held_steady_state_c(&pair, &boundary, 20.0, &[Some(80.0), None, None]).unwrap();
        // Nodes 1 and 2 split the 60 K drop in thirds.
        assert_eq!(temps[0], 80.0);
        assert!((temps[1] - 60.0).abs() < 1e-9, "{temps:?}");
        assert!((temps[2] - 40.0).abs() < 1e-9, "{temps:?}");
        // Everything held: the values; a free node with no conductance: none.
        let held = held_steady_state_c(&pair, &boundary, 20.0, &[Some(1.0), Some(2.0), Some(3.0)]);
        assert_eq!(held, Some([1.0, 2.0, 3.0]));
        let none = held_steady_state_c(&[[0.0; 3]; 3], &[0.0; 3], 20.0, &[Some(80.0), None, None]);
        assert_eq!(none, None);
    }

    #[test]
    fn a_limited_unread_element_starts_no_hotter_than_its_ceiling() {
        let mut temps = [90.0, 90.0, 90.0, 90.0];
        cap_unread_c(
            &mut temps,
            &[true, false, false, false],
            &[true, true, false, true],
            &[80.0, 80.0, 80.0, f32::NAN],
        );
        // Read, capped, unlimited, NaN ceiling.
        assert_eq!(temps, [90.0, 80.0, 90.0, 90.0]);
        let mut cool = [50.0];
        cap_unread_c(&mut cool, &[false], &[true], &[80.0]);
        assert_eq!(cool, [50.0]);
    }

    #[test]
    fn the_widening_of_a_limited_bound_stops_at_the_start_level() {
        // Room of 100 - 1 - 90 = 9 K.
        assert_eq!(capped_extra_k(20.0, 90.0, 100.0), 9.0);
        assert_eq!(capped_extra_k(2.0, 90.0, 100.0), 2.0);
        // The estimate alone already at or past the start's level.
        assert_eq!(capped_extra_k(2.0, 99.5, 100.0), 0.0);
        assert_eq!(capped_extra_k(2.0, 101.0, 100.0), 0.0);
        // No limit: as held; a NaN limit keeps it.
        assert_eq!(capped_extra_k(2.0, 90.0, f32::INFINITY), 2.0);
        assert_eq!(capped_extra_k(2.0, 90.0, f32::NAN), 2.0);
    }

    #[test]
    fn the_bound_widens_only_for_a_wider_covariance() {
        assert_eq!(bound_extra_k(0.25, 0.5, 3.0), 0.0);
        assert_eq!(bound_extra_k(0.01, 0.5, 3.0), 0.0);
        assert!((bound_extra_k(4.0, 0.5, 3.0) - 4.5).abs() < 1e-6);
        assert_eq!(bound_extra_k(f32::NAN, 0.5, 3.0), 0.0);
    }
}
