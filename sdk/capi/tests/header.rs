//! The committed C header is what cbindgen generates from the crate now.
//! Regenerate it with `FBKSD_REGENERATE_HEADER=1 cargo test -p fbksd-capi --test header`.

use std::path::Path;

fn generate() -> String {
    let dir = env!("CARGO_MANIFEST_DIR");
    let mut config = cbindgen::Config {
        language: cbindgen::Language::C,
        include_guard: Some("FBKSD_H".into()),
        header: Some(
            "/* The FBKSD C API (techniques, renderers, metrics). Generated from sdk/capi/src by cbindgen: do not edit. */"
                .into(),
        ),
        documentation: true,
        cpp_compat: true,
        usize_is_size_t: true,
        ..Default::default()
    };
    config.enumeration.rename_variants = cbindgen::RenameRule::ScreamingSnakeCase;
    config.enumeration.prefix_with_name = true;
    let mut out = Vec::new();
    cbindgen::Builder::new().with_crate(dir).with_config(config).generate().expect("cbindgen").write(&mut out);
    String::from_utf8(out).unwrap()
}

#[test]
fn the_committed_header_is_current() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("include/fbksd/fbksd.h");
    let fresh = generate();
    if std::env::var_os("FBKSD_REGENERATE_HEADER").is_some() {
        std::fs::write(&path, &fresh).unwrap();
    }
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        committed == fresh,
        "{} is stale: run FBKSD_REGENERATE_HEADER=1 cargo test -p fbksd-capi --test header",
        path.display()
    );
}
