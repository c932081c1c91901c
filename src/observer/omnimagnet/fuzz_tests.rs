//! Arbitrary inputs at the Omnimagnet's tick: currents, ambient and
//! thermocouple readings of any `f32` (NaN, infinities, extremes), each
//! reading present or not, elapsed times from 0 to 20 ms. Nothing panics,
//! the estimate stays finite, every current limit stays within
//! `[0, hardware_limit_a]`, and a current or an ambient that is not finite
//! is flagged on the tick that brought it, never used silently.

use super::*;
use crate::sensors::Reading;
use proptest::prelude::*;

/// A reading of `temp_c` \[degC\] sampled at `at_us`, or none.
fn reading(temp_c: Option<f32>, at_us: u32) -> Option<TimedReading> {
    temp_c.map(|temp_c| TimedReading {
        result: Ok(Reading::new(temp_c)),
        sampled_at_us: at_us,
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    #[test]
    fn any_tick_sequence_keeps_the_omnimagnet_finite_and_flags_what_it_drops(
        ticks in proptest::collection::vec(
            (
                proptest::array::uniform3(proptest::num::f32::ANY),
                proptest::num::f32::ANY,
                proptest::array::uniform6(proptest::option::of(proptest::num::f32::ANY)),
                0u32..20_000,
            ),
            1..150,
        )
    ) {
        let settings = OmniSettings::default();
        let observer =
            OmniObserver::new(&Omnimagnet::PAPER, &[22.0; NODES], 22.0, &settings).unwrap();
        let mut state = observer.state(&[22.0; NODES], 22.0);
        let mut now_us = 0u32;
        for (currents_a, ambient_c, readings_c, elapsed_us) in ticks {
            now_us = now_us.wrapping_add(elapsed_us);
            let inputs = OmniInputs {
                currents_a,
                ambient_c,
                readings: readings_c.map(|r| reading(r, now_us)),
                now_us,
                elapsed_us,
            };
            let out = *observer.tick(&mut state, &inputs);
            prop_assert!(out.temps_c.iter().all(|t| t.is_finite()), "{:?}", out.temps_c);
            let hardware_limit_a = settings.hardware_limit_a as f32;
            prop_assert!(
                out.limits
                    .iter()
                    .all(|l| (0.0..=hardware_limit_a).contains(&l.current_a)),
                "{:?}",
                out.limits
            );
            if currents_a.iter().any(|i| !i.is_finite()) {
                let flagged = out.flags.contains(InputFlags::CURRENT_NOT_FINITE);
                prop_assert!(flagged, "{:?}", out.flags);
            }
            if !ambient_c.is_finite() {
                let flagged = out.flags.contains(InputFlags::TEMPERATURE_INVALID);
                prop_assert!(flagged, "{:?}", out.flags);
            }
        }
    }
}
