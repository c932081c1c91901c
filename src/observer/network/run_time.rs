//! The network observer at a model's own size, on a host (the `alloc`
//! feature).
//!
//! A model file read on a host has its sizes at run time: a motor's
//! network from a design tool has hundreds of nodes. [`RunTimeObserver`]
//! is [`NetworkObserverOf`] of `Dyn` sizes: the same tick, correction,
//! protection and assembly as the MCU's [`NetworkObserver`](super::NetworkObserver),
//! its vectors `Vec`s and its matrices on the heap. It is built by
//! [`RunTimeObserver::build_at_run_time`] from any
//! [`NetworkDescription`] of [`RunTimeSizes`], through the solve the
//! builder runs (`GainSpec::solve`: the model, the gain in the bias
//! layout the settings ask for, the predictor, the shadow's block) and the
//! assembly
//! ([`NetworkObserverOf::assemble`]) that `from_parts` runs on an MCU's
//! tables. Test `the_run_time_observer_ticks_as_the_const_one`: a
//! network's observer built at run time ticks an hour of currents and
//! readings as the builder's, every published figure within `f32`
//! rounding.
//!
//! The model step in integer arithmetic
//! ([`NetworkSettings::integer_model_step`], with the `integer-step`
//! feature) is derived from the solved tables with the same scales as
//! the builder's (`FixedStep::of_entries`, `ConstFixedStep::of`'s twin).

use alloc::vec::Vec;

use nalgebra::Dyn;

use super::assemble::{Solved, StepMatrices};
use super::bias::BiasModeOf;
use super::resistance::SensorKind;
use super::solve::{GainSpec, Solution};
use super::{
    default_incidence_of, ModelOf, NetworkObserverOf, NetworkObserverStateOf, NetworkSettings,
};
use crate::error::{check, BuildError};
use crate::network::NetworkDescription;
use crate::observer::tables::invalid;
use crate::protect::derating::DeratingRule;
use crate::sizes::{RunTimeSizes, Sizes};

/// The network observer of a model's own size on a host.
pub type RunTimeObserver = NetworkObserverOf<RunTimeSizes, Dyn, Dyn>;

/// The state of a [`RunTimeObserver`] (the flavour that can run the
/// warm-up, as [`NetworkObserverStateOf`]'s default).
pub type RunTimeObserverState = NetworkObserverStateOf<RunTimeSizes, Dyn, Dyn>;

/// How the heat-input biases are laid out at sizes read at run time
/// ([`BiasModeOf`](super::BiasModeOf) of one flag per source).
pub type RunTimeBiasMode = BiasModeOf<Vec<bool>>;

/// What [`RunTimeObserver::build_at_run_time`] builds from, beside the
/// network: the builder's settings, one entry per node, source or sensor
/// (see [`NetworkObserverBuilder`](super::NetworkObserverBuilder), whose
/// methods name each).
#[derive(Debug, Clone, PartialEq)]
pub struct RunTimeSpec {
    /// The node each sensor measures.
    pub sensor_nodes: Vec<usize>,
    /// What each sensor is (one per sensor).
    pub sensor_kinds: Vec<SensorKind>,
    /// Each node's critical temperature \[degC\] (`None`: no limit).
    pub critical_c: Vec<Option<f64>>,
    /// `incidence[i][m]`: current `m` heats element `i` (`None`: the
    /// default incidence, [`default_incidence_of`]).
    pub incidence: Option<Vec<Vec<bool>>>,
    /// Each current's hardware limit \[A\].
    pub hardware_limit_a: Vec<f64>,
    /// The derating rule.
    pub rule: DeratingRule,
    /// The settings.
    pub settings: NetworkSettings,
    /// The sources whose heat-input bias is estimated.
    pub bias_sources: Vec<bool>,
    /// How the biases are laid out.
    pub bias_mode: RunTimeBiasMode,
}

impl RunTimeObserver {
    /// The observer of `network` at its own size (see the module docs).
    ///
    /// # Errors
    /// What [`NetworkObserverBuilder::build`](super::NetworkObserverBuilder::build)
    /// refuses, by the same names; [`BuildError::InvalidParameter`] naming
    /// a field of `spec` whose length is not the network's (or, for the
    /// sensors, zero).
    pub fn build_at_run_time<W: NetworkDescription<Sizes = RunTimeSizes>>(
        network: &W,
        spec: &RunTimeSpec,
    ) -> Result<Self, BuildError> {
        let sizes = network.sizes();
        let (n, b, m) = (sizes.nodes(), sizes.boundaries(), sizes.inputs());
        let s = &spec.settings;
        let p = spec.sensor_nodes.len();
        check(b >= 1 && m >= 1, "network")?;
        check(p >= 1, "sensor_nodes")?;
        check(spec.sensor_kinds.len() == p, "sensor_kinds")?;
        check(spec.critical_c.len() == n, "critical_c")?;
        check(spec.hardware_limit_a.len() == m, "hardware_limit_a")?;
        check(spec.bias_sources.len() == m, "bias_sources")?;
        if let Some(input) = (0..m).find(|k| network.joule_source_of(*k).is_none()) {
            return Err(BuildError::MissingSource { input });
        }
        let incidence = match &spec.incidence {
            Some(rows) => {
                check(
                    rows.len() == n && rows.iter().all(|row| row.len() == m),
                    "incidence",
                )?;
                rows.clone()
            }
            None => default_incidence_of(network, s.incidence_fraction)?,
        };
        if let BiasModeOf::Shared(mask) = &spec.bias_mode {
            check(mask.len() == m, "bias_mode")?;
        }
        // The filter's states: temperatures, biases, and the boundary
        // offset when the settings ask for one on a boundary that exists.
        let offset = s.boundary_offset.is_some_and(|o| o < b);
        let states = Dyn(n + m + usize::from(offset));
        let Solution {
            timing,
            model,
            gain,
            predictor,
            block,
        } = GainSpec {
            settings: s,
            sensor_nodes: &spec.sensor_nodes,
            kinds: &spec.sensor_kinds,
            critical_c: &spec.critical_c,
            hardware_limit_a: &spec.hardware_limit_a,
            bias_sources: &spec.bias_sources,
            bias_mode: spec.bias_mode.as_ref(),
        }
        .solve(network, states)?;
        let step = |model: ModelOf<RunTimeSizes>| StepMatrices {
            phi_minus_i: model.phi_minus_i,
            bd_power: model.bd_power,
            gd_boundary: model.gd_boundary,
            constant_k: model.constant_k,
        };
        let ad = model.ad.clone().cast::<f32>();
        let (source_node, resistance) = (model.source_node.clone(), model.resistance.clone());
        let (step, block) = (step(model), step(block));
        // As the builder's `integer_step` and `integer_block`: the block
        // in integer arithmetic where its tables fit, else in `f32`.
        let integer = if !s.integer_model_step {
            Ok((None, None))
        } else if cfg!(not(feature = "integer-step")) {
            Err(invalid(
                "integer_model_step (enable coil-thermal's integer-step feature)",
            ))
        } else {
            match step.fixed(sizes) {
                Some(fixed) => Ok((Some(fixed), block.fixed(sizes))),
                None => Err(invalid("model")),
            }
        };
        Self::assemble(
            s,
            Solved {
                sizes,
                sensor_nodes: spec.sensor_nodes.clone(),
                kinds: spec.sensor_kinds.clone(),
                critical_c: spec.critical_c.clone(),
                derating_product: spec.rule.product(),
                hardware_limit_a: spec.hardware_limit_a.clone(),
                incidence,
                ad,
                step,
                source_node,
                resistance,
                gain,
                predictor,
                block: (block, timing.correction_period),
                integer,
            },
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::network::{JouleSource, Network, Resistance};
    use crate::observer::network::{NetworkInputs, NetworkInputsOf, NetworkObserverBuilder};
    use crate::observer::TimedReading;
    use crate::sensors::Reading;

    /// A [`Network`] read as one of run-time sizes: the same description.
    struct AtRunTime<'a, const N: usize, const B: usize, const M: usize>(&'a Network<N, B, M>);

    impl<const N: usize, const B: usize, const M: usize> NetworkDescription for AtRunTime<'_, N, B, M> {
        type Sizes = RunTimeSizes;
        fn sizes(&self) -> RunTimeSizes {
            RunTimeSizes {
                nodes: N,
                boundaries: B,
                inputs: M,
            }
        }
        fn node_count(&self) -> usize {
            N
        }
        fn boundary_count(&self) -> usize {
            B
        }
        fn input_count(&self) -> usize {
            M
        }
        fn capacity_at_j_per_k(&self, node: usize) -> f64 {
            self.0.capacity_at_j_per_k(node)
        }
        fn later_pairs_w_per_k(&self, node: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
            self.0.later_pairs_w_per_k(node)
        }
        fn boundary_link_w_per_k(&self, node: usize, boundary: usize) -> f64 {
            self.0.boundary_link_w_per_k(node, boundary)
        }
        fn conductance_sum_w_per_k(&self, node: usize) -> f64 {
            self.0.conductance_sum_w_per_k(node)
        }
        fn fixed_power_at_w(&self, node: usize) -> f64 {
            self.0.fixed_power_at_w(node)
        }
        fn joule_source_of(&self, input: usize) -> Option<JouleSource> {
            self.0.joule_source_of(input)
        }
    }

    /// A winding in a slot and a housing, two currents (one heating each
    /// winding node), a thermocouple on the housing.
    fn network() -> Network<4, 1, 2> {
        Network::new([150.0, 80.0, 400.0, 900.0])
            .and_then(|net| net.connect(0, 1, 2.0))
            .and_then(|net| net.connect(0, 2, 3.0))
            .and_then(|net| net.connect(1, 2, 1.5))
            .and_then(|net| net.connect(2, 3, 6.0))
            .and_then(|net| net.connect_boundary(3, 0, 4.0))
            .and_then(|net| net.joule_source(0, 0, Resistance::with_alpha(0.12, 0.00393, 20.0)))
            .and_then(|net| net.joule_source(1, 1, Resistance::with_alpha(0.08, 0.00393, 20.0)))
            .unwrap()
    }

    fn spec(critical_c: [Option<f64>; 4], settings: NetworkSettings) -> RunTimeSpec {
        RunTimeSpec {
            sensor_nodes: alloc::vec![3],
            sensor_kinds: alloc::vec![SensorKind::Thermocouple],
            critical_c: critical_c.to_vec(),
            incidence: None,
            hardware_limit_a: alloc::vec![12.0, 12.0],
            rule: DeratingRule::omnimagnet(),
            settings,
            bias_sources: alloc::vec![true, true],
            bias_mode: RunTimeBiasMode::Auto,
        }
    }

    #[test]
    fn a_spec_of_other_sizes_is_refused_by_name() {
        let net = network();
        let good = spec([Some(155.0), None, None, None], NetworkSettings::DEFAULT);
        let refused = |change: &dyn Fn(&mut RunTimeSpec)| {
            let mut spec = good.clone();
            change(&mut spec);
            match RunTimeObserver::build_at_run_time(&AtRunTime(&net), &spec) {
                Err(BuildError::InvalidParameter { name }) => name,
                other => panic!(
                    "expected a refusal, got {:?}",
                    other.map(|o| o.fingerprint())
                ),
            }
        };
        assert!(RunTimeObserver::build_at_run_time(&AtRunTime(&net), &good).is_ok());
        assert_eq!(refused(&|s| s.critical_c.truncate(3)), "critical_c");
        assert_eq!(
            refused(&|s| s.hardware_limit_a.push(1.0)),
            "hardware_limit_a"
        );
        assert_eq!(refused(&|s| s.sensor_nodes.clear()), "sensor_nodes");
        assert_eq!(
            refused(&|s| s.sensor_kinds = alloc::vec![SensorKind::Thermocouple; 2]),
            "sensor_kinds"
        );
        assert_eq!(refused(&|s| s.bias_sources.clear()), "bias_sources");
        assert_eq!(
            refused(&|s| s.incidence = Some(alloc::vec![alloc::vec![true; 2]; 3])),
            "incidence"
        );
        // Checked by the assembly, as for the MCU's tables.
        assert_eq!(
            refused(&|s| {
                s.sensor_nodes = alloc::vec![4];
                s.sensor_kinds = alloc::vec![SensorKind::Thermocouple];
            }),
            "sensor_nodes"
        );
    }

    #[test]
    fn the_run_time_observer_ticks_as_the_const_one() {
        ticks_as_the_const_one(
            NetworkSettings {
                correction_period_s: 1.0,
                ..NetworkSettings::DEFAULT
            },
            3_600_000,
        );
    }

    /// The model step in integer arithmetic, derived at run time, is the
    /// builder's: half an hour to the bit.
    #[cfg(feature = "integer-step")]
    #[test]
    fn the_run_time_integer_step_ticks_as_the_const_one() {
        ticks_as_the_const_one(
            NetworkSettings {
                correction_period_s: 1.0,
                integer_model_step: true,
                ..NetworkSettings::DEFAULT
            },
            1_800_000,
        );
    }

    /// `ticks` ticks of the run-time observer and the builder's with
    /// `settings`: every published figure to the bit.
    fn ticks_as_the_const_one(settings: NetworkSettings, ticks: u32) {
        let net = network();
        let critical_c = [Some(155.0), Some(155.0), None, None];
        let builder = NetworkObserverBuilder::new(&net, [3])
            .critical_c(critical_c)
            .hardware_limit_a([12.0, 12.0])
            .settings(settings);
        let fixed = builder.build::<6>().unwrap();
        let spec = spec(critical_c, settings);
        let dynamic = RunTimeObserver::build_at_run_time(&AtRunTime(&net), &spec).unwrap();
        assert_eq!(dynamic.sizes().nodes, 4);
        let mut fixed_state = fixed.state(&[20.0; 4], &[20.0]);
        let mut dynamic_state = dynamic.state(&alloc::vec![20.0; 4], &alloc::vec![20.0]);
        let mut now_us = 0u32;
        // 10 A and 6 A, then a step to 14 A; the housing's thermocouple
        // reads 2 K above the model each second.
        for tick in 0..ticks {
            let currents_a = if tick < ticks / 2 {
                [10.0, 6.0]
            } else {
                [14.0, 6.0]
            };
            let reading = (tick % 1000 == 0).then(|| TimedReading {
                result: Ok(Reading::new(fixed_state.outputs().temps_c[3] + 2.0)),
                sampled_at_us: now_us,
            });
            let inputs: NetworkInputs<1, 2, 1> = NetworkInputsOf {
                currents_a,
                boundary_c: [20.0],
                readings: [reading],
                now_us,
                elapsed_us: 1000,
            };
            let at_run_time = NetworkInputsOf::<Dyn, Dyn, Dyn> {
                currents_a: currents_a.to_vec(),
                boundary_c: alloc::vec![20.0],
                readings: alloc::vec![reading],
                now_us,
                elapsed_us: 1000,
            };
            let a = *fixed.tick(&mut fixed_state, &inputs);
            let b = dynamic.tick(&mut dynamic_state, &at_run_time);
            // To the bit: the same operations in the same order.
            assert_eq!(a.temps_c[..], b.temps_c[..], "tick {tick}");
            assert_eq!(a.upper_c[..], b.upper_c[..], "tick {tick}");
            assert_eq!(a.limits[..], b.limits[..], "tick {tick}");
            assert_eq!(a.time_to_limit_s[..], b.time_to_limit_s[..], "tick {tick}");
            assert_eq!(a.sensors[..], b.sensors[..], "tick {tick}");
            assert_eq!(
                (a.alarm, a.corrected, a.flags, a.steps),
                (b.alarm, b.corrected, b.flags, b.steps),
                "tick {tick}"
            );
            now_us = now_us.wrapping_add(1000);
        }
        // The windings heated, the sensor corrected, a limit was derated.
        let out = fixed_state.outputs();
        assert!(out.temps_c[0] > 60.0, "{:?}", out.temps_c);
        assert_eq!(
            fixed.heat_bias_w(&fixed_state)[..],
            dynamic.heat_bias_w(&dynamic_state)[..]
        );
        assert_eq!(fixed.fingerprint(), dynamic.fingerprint());
    }
}
