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
//! # The restore with an unknown off time
//!
//! A snapshot says where the device was when it was saved; without a clock
//! the off time is only known to lie between 0 and the snapshot's age.
//! Every off time in that range gives a state (the exact zero-current
//! cooling of the saved one), and the readings at the restore say which
//! are possible: [`earliest_off_time_s`] finds the *shortest* off time
//! that cools some sensor's node to its reading (plus a tolerance; every
//! sensor's node is then set no warmer than its reading), the least
//! cooling the readings allow, so the unmeasured nodes err hot and the
//! measured ones agree with their sensors from the first correction (no
//! healthy reading refused, no "colder than the physics").

/// How far below its alarm limit the start puts the protective upper bound
/// of a limited element no sensor reads \[K\]: below the shutdown level
/// (the start never latches), inside the limiter's taper band (the current
/// is limited until the sensors say more).
pub const START_BELOW_LIMIT_K: f32 = 1.0;

/// The start's warm-up ends when every variance of the covariance it holds
/// is within this share of the steady posterior's (dimensionless).
pub const SETTLED_FRACTION: f32 = 0.05;

/// The most corrections the start's warm-up runs before the steady gain
/// takes over whatever its covariance: at a 0.5 s correction period, 9 h.
pub const MAX_START_CORRECTIONS: u16 = u16::MAX;

/// Off times [`earliest_off_time_s`] tries on a geometric grid before it
/// refines the first that fits.
const OFF_TIME_GRID: u32 = 32;
/// Bisection steps of that refinement: the bracket shrinks `2^20`-fold.
const OFF_TIME_BISECTIONS: u32 = 20;

/// The standard deviation \[K\] the start gives each node: `None` for a
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
pub fn start_sigma_k<const N: usize>(
    read: &[bool; N],
    steady_upper_c: &[f32; N],
    limits_c: &[f32; N],
    limited: &[bool; N],
    steady_sigma_k: &[f32; N],
    k_sigma: f32,
) -> [Option<f32>; N] {
    let k = if k_sigma >= 1.0 { k_sigma } else { 1.0 };
    let gap_k = |i: usize| {
        let gap = limits_c[i] - START_BELOW_LIMIT_K - steady_upper_c[i];
        if gap.is_finite() && gap > 0.0 {
            gap
        } else {
            0.0
        }
    };
    let widest_k = (0..N)
        .filter(|i| limited[*i] && !read[*i])
        .map(gap_k)
        .fold(0.0f32, f32::max);
    core::array::from_fn(|i| {
        if read[i] {
            return None;
        }
        let gap = if limited[i] { gap_k(i) } else { widest_k };
        Some(steady_sigma_k[i] + gap / k)
    })
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

/// The shortest off time \[s\] in `[0, max_off_s]` after which the cooled
/// state (`cooled(t)`, the node temperatures \[degC\] after `t` \[s\] off)
/// puts some sensor with a reading no more than `tolerance_k` \[K\] above
/// it: the least cooling the readings allow (see the module docs; where
/// the sensors disagree, the one that cooled least decides, and the
/// others' nodes are the caller's to set to their readings).
///
/// `0` when no reading is usable (nothing says the device cooled) or the
/// saved state already fits; `max_off_s` when none fits (the readings are
/// colder than the device can have cooled: the most cooling there was
/// time for, and the filter does the rest). A geometric grid of 32
/// (`OFF_TIME_GRID`) off times from 1 s, then 20 (`OFF_TIME_BISECTIONS`)
/// bisections between the last that does not fit and the first that does:
/// at most 53 evaluations of `cooled`, at the restore (never in a tick).
pub fn earliest_off_time_s<const N: usize, const P: usize>(
    cooled: impl Fn(f32) -> [f32; N],
    sensor_nodes: &[usize; P],
    readings_c: &[Option<f32>; P],
    tolerance_k: f32,
    max_off_s: f32,
) -> f32 {
    let usable = readings_c.iter().any(|r| r.is_some_and(f32::is_finite));
    if !usable || max_off_s.is_nan() || max_off_s <= 0.0 || !max_off_s.is_finite() {
        return 0.0;
    }
    let fits = |t: f32| {
        let temps = cooled(t);
        readings_c.iter().zip(sensor_nodes).any(|(r, node)| {
            match (r.filter(|r| r.is_finite()), temps.get(*node)) {
                (Some(reading), Some(model)) => *model <= reading + tolerance_k,
                _ => false,
            }
        })
    };
    if fits(0.0) {
        return 0.0;
    }
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
        let sigma = start_sigma_k(
            &[true, false, false],
            &[30.0, 40.0, 35.0],
            &[100.0, 100.0, 1e9],
            &[true, true, false],
            &[0.1, 0.5, 0.7],
            3.0,
        );
        assert_eq!(sigma[0], None);
        let s1 = sigma[1].unwrap();
        // Upper bound = steady bound + k (sigma - steady sigma).
        assert!((40.0 + 3.0 * (s1 - 0.5) - (100.0 - START_BELOW_LIMIT_K)).abs() < 1e-4);
        assert!((sigma[2].unwrap() - (0.7 + (s1 - 0.5))).abs() < 1e-5);
        // An element already past that level keeps its steady deviation.
        let hot = start_sigma_k(&[false], &[120.0], &[100.0], &[true], &[0.5], 3.0);
        assert_eq!(hot, [Some(0.5)]);
    }

    #[test]
    fn the_bound_widens_only_for_a_wider_covariance() {
        assert_eq!(bound_extra_k(0.25, 0.5, 3.0), 0.0);
        assert_eq!(bound_extra_k(0.01, 0.5, 3.0), 0.0);
        assert!((bound_extra_k(4.0, 0.5, 3.0) - 4.5).abs() < 1e-6);
        assert_eq!(bound_extra_k(f32::NAN, 0.5, 3.0), 0.0);
    }
}
