//! The documented example cannot drift from the shipped model file.

use coil_thermal_host::model_file::ModelFile;

#[test]
fn the_format_documents_example_is_the_shipped_hust_model() {
    let full = include_str!("../MODEL_FORMAT.md");
    let doc = &full[full.find("## A full example").expect("the full example")..];
    let start = doc.find("```toml\n").expect("a toml example") + "```toml\n".len();
    let end = start + doc[start..].find("```").expect("closed block");
    let from_doc = ModelFile::parse(&doc[start..end], "MODEL_FORMAT.md").unwrap();
    let shipped = ModelFile::load(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/models/hust-ipmsm-3node.toml"
    )))
    .unwrap();
    assert_eq!(from_doc, shipped);
}

#[test]
fn every_shipped_model_loads() {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/models");
    let mut n = 0;
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            ModelFile::load(&path).unwrap_or_else(|e| panic!("{e:#}"));
            n += 1;
        }
    }
    assert!(n >= 2);
}

/// `Model::source_kinds` is the network's source order, which the replays'
/// effective currents and `codegen`'s generated currents both follow: on
/// every shipped model, each kind names the node its network source heats
/// (a `[[source]]`'s and a `[[speed_loss]]`'s `node`, a `[[loss]]`'s first
/// or second of `nodes`), and there is one kind per source.
#[test]
fn source_kinds_follow_the_network_sources() {
    use coil_thermal_host::model_file::{Model, SourceKind};
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/models");
    let mut kinds_seen = [false; 3];
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "toml") {
            continue;
        }
        let file = ModelFile::load(&path).unwrap();
        let model = Model::build(&file).unwrap();
        let sources = model.network.sources();
        let kinds: Vec<SourceKind> = model.source_kinds().collect();
        assert_eq!(kinds.len(), sources.len(), "{}", path.display());
        for (kind, source) in kinds.iter().zip(sources) {
            let (expected, seen) = match *kind {
                SourceKind::Drive(k) => (&file.sources[k].node, 0),
                SourceKind::SpeedLoss(k) => (&file.speed_losses[k].node, 1),
                SourceKind::Loss { k, second } => (&file.losses[k].nodes[usize::from(second)], 2),
            };
            kinds_seen[seen] = true;
            assert_eq!(
                &model.nodes[source.node],
                expected,
                "{}: {kind:?}",
                path.display()
            );
        }
    }
    assert_eq!(kinds_seen, [true; 3], "a shipped model of every kind");
}
