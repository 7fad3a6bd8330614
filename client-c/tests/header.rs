//! The committed C header is what cbindgen generates from `src/lib.rs` now. Fails with the
//! command that regenerates it when someone changed the exported API and not the header.

use std::path::Path;

#[test]
fn the_committed_header_is_up_to_date() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let config =
        cbindgen::Config::from_file(root.join("cbindgen.toml")).expect("client-c/cbindgen.toml");
    let bindings = cbindgen::Builder::new()
        .with_config(config)
        .with_src(root.join("src/lib.rs"))
        .generate()
        .expect("cbindgen generates the header from client-c/src/lib.rs");
    let mut generated = Vec::new();
    bindings.write(&mut generated);
    let generated = String::from_utf8(generated).expect("the header is UTF-8");

    let path = root.join("include/dear_client.h");
    if std::env::var_os("DEAR_UPDATE_HEADER").is_some() {
        std::fs::write(&path, &generated).expect("write client-c/include/dear_client.h");
        return;
    }
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    if committed != generated {
        let first_difference = committed
            .lines()
            .zip(generated.lines())
            .position(|(a, b)| a != b)
            .unwrap_or(committed.lines().count().min(generated.lines().count()));
        panic!(
            "client-c/include/dear_client.h differs from what cbindgen generates from \
             client-c/src/lib.rs (first at line {}: committed {:?}, generated {:?}); \
             regenerate it with\n\n    DEAR_UPDATE_HEADER=1 cargo test -p dear-client-c --test header\n",
            first_difference + 1,
            committed.lines().nth(first_difference).unwrap_or("<end>"),
            generated.lines().nth(first_difference).unwrap_or("<end>"),
        );
    }
}
