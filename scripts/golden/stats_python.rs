// The Python of the statistics checks against pingouin, krippendorff and statsmodels, shared by
// analysis/tests/reliability_interop.rs and analysis/tests/power_interop.rs (each includes this
// file with `#[path]`), following scripts/golden/bayes_python.rs.

use std::path::{Path, PathBuf};
use std::process::Command;

/// The Python that can import `module`: `$STATS_PYTHON` (which scripts/test points at the venv
/// it makes, `target/stats-env`, pins in scripts/reference/stats-requirements.txt), else that
/// venv itself. Under `CI` a missing interpreter or package fails the test that asks (`what`);
/// elsewhere it returns `None` after saying why the test skips.
pub fn python(module: &str, what: &str) -> Option<PathBuf> {
    let ci = std::env::var_os("CI").is_some();
    let venv = Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/stats-env/bin/python");
    let python = match std::env::var_os("STATS_PYTHON") {
        Some(p) => PathBuf::from(p),
        None if venv.exists() => venv,
        None if ci => panic!(
            "neither STATS_PYTHON nor {} is there: under CI the {what} needs the venv \
             scripts/test makes",
            venv.display()
        ),
        None => {
            eprintln!("{what} skipped: no STATS_PYTHON and no target/stats-env");
            return None;
        }
    };
    match Command::new(&python)
        .args(["-c", &format!("import {module}")])
        .output()
    {
        Ok(o) if o.status.success() => Some(python),
        Ok(o) if ci => panic!(
            "{} cannot import {module}:\n{}",
            python.display(),
            String::from_utf8_lossy(&o.stderr)
        ),
        Err(e) if ci => panic!("cannot run {}: {e}", python.display()),
        _ => {
            eprintln!("{what} skipped: {} lacks {module}", python.display());
            None
        }
    }
}

/// Runs `scripts/reference/<script>` with `python` on `cases` (written to a fresh temporary
/// file named after `tag`) and returns the JSON it prints; a failing script fails the test
/// with its stderr.
pub fn run_script(
    python: &Path,
    script: &str,
    tag: &str,
    cases: &serde_json::Value,
) -> serde_json::Value {
    let dir = std::env::temp_dir().join(format!("{tag}_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("cases.json");
    std::fs::write(&file, serde_json::to_string(cases).unwrap()).unwrap();
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scripts/reference")
        .join(script);
    let out = Command::new(python).arg(&path).arg(&file).output().unwrap();
    assert!(
        out.status.success(),
        "{script} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    std::fs::remove_dir_all(&dir).unwrap();
    serde_json::from_slice(&out.stdout).unwrap()
}
