//! Whether python3 has a module that a test checks the crate against (a standard
//! URDF parser, numpy's own files). `npm test` installs them (scripts/setup.sh), so
//! in CI a missing module fails the test; elsewhere the test is skipped with a note.

use std::process::Command;

/// True when `python3 -c "import MODULE"` succeeds; panics in CI when it does not.
pub fn python_has(module: &str) -> bool {
    let ok = Command::new("python3")
        .args(["-c", &format!("import {module}")])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    if !ok {
        assert!(
            std::env::var_os("CI").is_none(),
            "{module} is not installed (scripts/setup.sh installs it)"
        );
        eprintln!("skip: python3 with {module} not available (pip install {module})");
    }
    ok
}
