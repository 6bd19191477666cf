//! The `gsart` command line: a thin layer over the core.

#[cfg(not(target_arch = "wasm32"))]
fn main() {
    eprintln!("gsart: no commands yet");
    std::process::exit(2);
}

#[cfg(target_arch = "wasm32")]
fn main() {}
