//! `[observer] sensors` entries with a kind (issue 38, item 5): a node name
//! stays a thermocouple (every model file before kinds reads the same), an
//! inline table names a resistive sensor on the ADC or a winding's
//! resistance; every bad entry is refused naming its key, and no input
//! panics the parser.

use coil_thermal::sensors::SensorFault;
use coil_thermal_host::firmware::FirmwareConfig;
use coil_thermal_host::model_file::{Model, ModelFile};
use coil_thermal_host::sensor_kinds::SensorKindSpec;
use proptest::prelude::*;

/// The valve of `host-tests/models/solenoid-valve-24v.toml`, with its
/// `[observer] sensors` line replaced by `sensors`.
fn valve(sensors: &str) -> String {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/models/solenoid-valve-24v.toml"
    );
    let text = std::fs::read_to_string(path).unwrap();
    text.replace("sensors = [\"housing\"]", &format!("sensors = [{sensors}]"))
}

fn parse(sensors: &str) -> anyhow::Result<ModelFile> {
    ModelFile::parse(&valve(sensors), "valve.toml")
}

fn refusal(sensors: &str) -> String {
    match parse(sensors) {
        Ok(_) => panic!("accepted: {sensors}"),
        Err(e) => format!("{e:#}"),
    }
}

const NTC: &str = r#"{ node = "coil", kind = "ntc", beta_k = 3950, r25_ohm = 10000, r_ref_ohm = 10000, topology = "sensor_to_ground", adc_bits = 12 }"#;

#[test]
fn every_shipped_model_file_still_reads_and_writes_back_the_same() {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/models");
    let mut with_sensors = 0;
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "toml") {
            continue;
        }
        let file = ModelFile::load(&path).unwrap();
        if let Some(observer) = &file.observer {
            for s in &observer.sensors {
                // Every file before kinds names thermocouples; the NTC and
                // the resistance examples are the files written with a kind.
                if path.ends_with("drive-3node-ntc.toml") {
                    assert_eq!(s.kind_name(), "ntc");
                } else if path.ends_with("drive-3node-resistance.toml") {
                    assert_eq!(s.kind_name(), "resistance");
                } else {
                    assert_eq!(s.kind, SensorKindSpec::Thermocouple, "{}", path.display());
                    with_sensors += 1;
                }
            }
        }
        let again = ModelFile::parse(&file.to_toml().unwrap(), "again.toml").unwrap();
        assert_eq!(again, file, "{}", path.display());
    }
    assert!(with_sensors >= 7, "{with_sensors}");
}

#[test]
fn an_ntc_entry_is_the_library_conversion_of_its_divider() {
    let file = parse(&format!(r#""housing", {NTC}"#)).unwrap();
    let model = Model::build(&file).unwrap();
    let config = FirmwareConfig::of(&model, file.observer.as_ref()).unwrap();
    assert_eq!(config.sensor_nodes, [1, 0]);
    let ntc = &config.sensors[1];
    assert_eq!(ntc.kind_name(), "ntc");
    // Half scale: the NTC equals R_ref, 10 kohm, which the beta equation
    // puts at its T0 = 25 degC exactly.
    let reading = ntc.convert_counts(2048).unwrap().unwrap();
    assert!((reading.temp_c - 25.0).abs() < 1e-3, "{}", reading.temp_c);
    // 30 degC by the beta equation: R = R25 exp(B (1/T - 1/T25)), the
    // node at R / (R + R_ref) of 4096 counts.
    let r = 10_000.0 * (3950.0 * (1.0 / 303.15 - 1.0 / 298.15_f64)).exp();
    let counts = (4096.0 * r / (r + 10_000.0)).round() as u32;
    let t = ntc.convert_counts(counts).unwrap().unwrap().temp_c;
    assert!((t - 30.0).abs() < 0.05, "{t}");
    // The rails are faults, never temperatures.
    assert_eq!(
        ntc.convert_counts(4095),
        Some(Err(SensorFault::OpenCircuit))
    );
    assert_eq!(ntc.convert_counts(0), Some(Err(SensorFault::ShortToGnd)));
    // A thermocouple's column is a temperature: no counts.
    assert_eq!(config.sensors[0].convert_counts(2048), None);
    // Written back, it reads the same.
    let again = ModelFile::parse(&file.to_toml().unwrap(), "again.toml").unwrap();
    assert_eq!(again, file);
}

#[test]
fn kty_platinum_steinhart_hart_and_resistance_entries_read() {
    let file = parse(
        r#"
        { node = "coil", kind = "kty84", r_ref_ohm = 1000, topology = "sensor_to_supply", adc_bits = 12 },
        { node = "coil", kind = "kty83", r_ref_ohm = 1000, topology = "sensor_to_ground", adc_bits = 16, rail_margin_counts = 8 },
        { node = "housing", kind = "pt1000", r_ref_ohm = 1000, topology = "sensor_to_ground", adc_bits = 12, min_c = -40, max_c = 200 },
        { node = "housing", kind = "ntc", steinhart_hart = [1.009249522e-3, 2.378405444e-4, 2.019202697e-7], r_ref_ohm = 10000, topology = "sensor_to_ground", adc_bits = 12 },
        { source = "coil", kind = "resistance", noise_fraction = 0.01, min_current_a = 0.05 },
        { node = "housing", kind = "thermocouple" }
        "#,
    )
    .unwrap();
    let model = Model::build(&file).unwrap();
    let config = FirmwareConfig::of(&model, file.observer.as_ref()).unwrap();
    // The resistance sensor is of the node its source heats.
    assert_eq!(config.sensor_nodes, [0, 0, 1, 1, 0, 1]);
    let kinds: Vec<_> = config.sensors.iter().map(|s| s.kind_name()).collect();
    assert_eq!(
        kinds,
        [
            "kty84",
            "kty83",
            "pt1000",
            "ntc",
            "resistance",
            "thermocouple"
        ]
    );
    // KTY84-130 to supply on 1 kohm: half scale is 1000 ohm, the
    // datasheet's 100 degC row.
    let t = config.sensors[0]
        .convert_counts(2048)
        .unwrap()
        .unwrap()
        .temp_c;
    assert!((t - 100.0).abs() < 1e-3, "{t}");
    // PT1000 on 1 kohm at half scale: 1000 ohm, 0 degC (IEC 60751 R0).
    let t = config.sensors[2]
        .convert_counts(2048)
        .unwrap()
        .unwrap()
        .temp_c;
    assert!(t.abs() < 1e-3, "{t}");
    // Its narrowed range: 1 kohm x 4095/1 is far above 200 degC.
    assert_eq!(
        config.sensors[2].convert_counts(4000),
        Some(Err(SensorFault::OutOfRange))
    );
    // The KTY83's rail margin widens the rails.
    assert_eq!(
        config.sensors[1].convert_counts(65535 - 8),
        Some(Err(SensorFault::OpenCircuit))
    );
    // The resistance is the library's sensor of source 0 on its node,
    // through the source's own `R(T)` (no measured one given); the others
    // are temperatures.
    let r = config.sensor_kinds[4].resistance().copied().unwrap();
    assert_eq!((r.source, r.node), (0, 0));
    assert_eq!(r.noise_fraction, 0.01);
    assert_eq!(r.min_current_a, 0.05);
    assert_eq!(
        (r.r_at_0c_ohm, r.slope_ohm_per_k),
        (
            model.drives[0].resistance.r_at_0c_ohm,
            model.drives[0].resistance.slope_ohm_per_k
        )
    );
    assert!(config
        .sensor_kinds
        .iter()
        .enumerate()
        .all(|(j, k)| (j == 4) == k.resistance().is_some()));
    // `calibrate --validate` scores temperatures against temperatures: it
    // refuses a resistance, by name.
    let e = config
        .require_temperature_sensors("calibrate --validate")
        .unwrap_err()
        .to_string();
    assert!(e.contains("resistance of coil"), "{e}");
}

#[test]
fn bad_entries_are_refused_naming_the_key() {
    let ntc = |extra: &str| {
        format!(
            r#"{{ node = "coil", kind = "ntc", r_ref_ohm = 10000, topology = "sensor_to_ground", {extra} }}"#
        )
    };
    for (sensors, key) in [
        // A unit the key does not have.
        (ntc("adc_bits = 12, beta_k = 3950, r25_kohm = 10"), "r25_kohm"),
        // A string for a number.
        (ntc(r#"adc_bits = 12, beta_k = "3950", r25_ohm = 10000"#), "beta_k"),
        // Impossible values.
        (ntc("adc_bits = 32, beta_k = 3950, r25_ohm = 10000"), "adc_bits"),
        (ntc("adc_bits = 12.5, beta_k = 3950, r25_ohm = 10000"), "adc_bits"),
        (ntc("adc_bits = 12, beta_k = -3950, r25_ohm = 10000"), "beta_k"),
        (ntc("adc_bits = 12, beta_k = 3950, r25_ohm = 0"), "r25_ohm"),
        (ntc("adc_bits = 12, beta_k = 3950, r25_ohm = 10000, t0_c = -300"), "t0_c"),
        (ntc("adc_bits = 12, beta_k = 3950, r25_ohm = 10000, min_c = 100, max_c = 0"), "max_c"),
        (ntc("adc_bits = 12, beta_k = 3950, r25_ohm = 10000, min_c = 0"), "max_c"),
        (ntc("adc_bits = 12, beta_k = 3950"), "r25_ohm"),
        (ntc("adc_bits = 12"), "beta_k"),
        (ntc("adc_bits = 12, steinhart_hart = [1e-3, 2e-4]"), "steinhart_hart"),
        (ntc("adc_bits = 12, steinhart_hart = [1e-3, -2e-4, 1e-7]"), "steinhart_hart"),
        (ntc("adc_bits = 12, beta_k = 3950, r25_ohm = 1e4, rail_margin_counts = 3000"), "rail_margin_counts"),
        (
            r#"{ node = "coil", kind = "kty84", r_ref_ohm = -1, topology = "sensor_to_ground", adc_bits = 12 }"#.into(),
            "r_ref_ohm",
        ),
        (
            r#"{ node = "coil", kind = "kty84", r_ref_ohm = 1000, topology = "pull_up", adc_bits = 12 }"#.into(),
            "topology",
        ),
        // A curve key on a kind whose curve is its datasheet's.
        (
            r#"{ node = "coil", kind = "kty84", beta_k = 3950, r_ref_ohm = 1000, topology = "sensor_to_ground", adc_bits = 12 }"#.into(),
            "beta_k",
        ),
        (r#"{ node = "coil", kind = "ptc" }"#.into(), "ptc"),
        (r#"{ node = "coil" }"#.into(), "kind"),
        (r#"{ kind = "thermocouple" }"#.into(), "node"),
        (r#"{ node = "coil", kind = "thermocouple", noise = 1 }"#.into(), "noise"),
        (
            r#"{ node = "coil", kind = "resistance", noise_fraction = 0.01, min_current_a = 0.1 }"#.into(),
            "node",
        ),
        (
            r#"{ source = "coil", kind = "resistance", noise_fraction = 0, min_current_a = 0.1 }"#.into(),
            "noise_fraction",
        ),
        (
            r#"{ source = "coil", kind = "resistance", noise_fraction = 0.01 }"#.into(),
            "min_current_a",
        ),
        (
            r#"{ source = "coil", kind = "resistance", noise_fraction = 0.01, min_current_a = 0.1, r_at_0c_ohm = 50 }"#.into(),
            "slope_ohm_per_k",
        ),
    ] {
        let e = refusal(&sensors);
        assert!(e.contains(&format!("`{key}`")), "{sensors}\n  -> {e}");
    }
    // Names that resolve against the model: an unknown node or source.
    let file = parse(
        r#"{ source = "pump", kind = "resistance", noise_fraction = 0.01, min_current_a = 0.1 }"#,
    )
    .unwrap();
    let model = Model::build(&file).unwrap();
    let e = FirmwareConfig::of(&model, file.observer.as_ref()).unwrap_err();
    assert!(format!("{e:#}").contains("`pump`"), "{e:#}");
    let file = parse(&NTC.replace("\"coil\"", "\"end_turns\"")).unwrap();
    let model = Model::build(&file).unwrap();
    assert!(FirmwareConfig::of(&model, file.observer.as_ref()).is_err());
}

const KEYS: [&str; 14] = [
    "node",
    "kind",
    "source",
    "beta_k",
    "r25_ohm",
    "r_ref_ohm",
    "topology",
    "adc_bits",
    "rail_margin_counts",
    "min_c",
    "max_c",
    "steinhart_hart",
    "noise_fraction",
    "min_current_a",
];

fn any_value() -> impl Strategy<Value = String> {
    prop_oneof![
        any::<f64>().prop_map(|v| if v.is_finite() {
            format!("{v:e}")
        } else if v.is_nan() {
            "nan".into()
        } else if v > 0.0 {
            "inf".into()
        } else {
            "-inf".into()
        }),
        any::<i64>().prop_map(|v| v.to_string()),
        prop_oneof![
            Just("\"coil\""),
            Just("\"housing\""),
            Just("\"ntc\""),
            Just("\"kty83\""),
            Just("\"kty84\""),
            Just("\"pt100\""),
            Just("\"pt1000\""),
            Just("\"resistance\""),
            Just("\"thermocouple\""),
            Just("\"sensor_to_ground\""),
            Just("\"sensor_to_supply\""),
            Just("\"\""),
            Just("[1e-3, 2e-4, 1e-7]"),
            Just("[]"),
            Just("true"),
        ]
        .prop_map(String::from),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(3000))]

    /// Any inline table of the keys a sensor takes, any values: a file
    /// that reads or a refusal, never a panic; what reads converts every
    /// count without one either.
    #[test]
    fn no_entry_panics_the_parser(
        pairs in proptest::collection::btree_map(0usize..KEYS.len(), any_value(), 0..9),
        counts in any::<u32>(),
    ) {
        let body: Vec<String> = pairs.iter().map(|(k, v)| format!("{} = {v}", KEYS[*k])).collect();
        let sensors = format!("{{ {} }}", body.join(", "));
        if let Ok(file) = parse(&sensors) {
            if let Ok(model) = Model::build(&file) {
                if let Ok(config) = FirmwareConfig::of(&model, file.observer.as_ref()) {
                    for s in &config.sensors {
                        if let Some(Ok(r)) = s.convert_counts(counts) {
                            prop_assert!(r.temp_c.is_finite());
                        }
                    }
                }
            }
        }
    }

    /// Arbitrary text in place of the list: never a panic.
    #[test]
    fn no_text_panics_the_parser(text in "\\PC{0,80}") {
        let _ = parse(&text);
    }
}
