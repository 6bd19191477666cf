//! Determinism across platforms: a small Step-1 fit must reproduce the labels stored in
//! `tests/data/small_fit_labels.json`; the wasm suites check the same file in Chromium,
//! so native and wasm give the same labels for the same seed. After an intended change
//! to the fit, regenerate the file with `GSART_BLESS=1 cargo test --test fit_golden`.

mod common_small_fit;

#[test]
fn small_fit_matches_the_golden_labels() {
    let labels = common_small_fit::small_fit_labels();
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/small_fit_labels.json"
    );
    if std::env::var_os("GSART_BLESS").is_some() {
        std::fs::write(path, serde_json::to_string(&labels).unwrap()).unwrap();
        return;
    }
    let golden: Vec<u32> = serde_json::from_str(common_small_fit::GOLDEN).unwrap();
    assert_eq!(
        labels, golden,
        "labels changed: bless the golden file if intended"
    );
    // The fit did segment something: both laptop halves carry labels.
    let mut used: Vec<u32> = labels.clone();
    used.sort_unstable();
    used.dedup();
    assert!(used.len() >= 2, "{used:?}");
}
