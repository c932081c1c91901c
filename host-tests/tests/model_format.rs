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
