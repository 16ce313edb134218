// The Pythons of the checks against outside tools, shared by every test that runs one (each
// includes this file with `#[path]`): the venvs scripts/test makes, each with its pins in
// scripts/reference/*-requirements.txt. A test uses one venv and some of these items.
#![allow(dead_code, reason = "each test uses the venvs and the runner it needs")]

use std::path::{Path, PathBuf};
use std::process::Command;

/// A venv of `target/` and the variable that names its Python.
pub struct Venv {
    /// The environment variable scripts/test sets to the venv's Python.
    var: &'static str,
    /// The venv's folder under `target/`.
    dir: &'static str,
}

/// questplus, psignifit, choix, SciPy (`target/bayes-env`, bayes-requirements.txt).
pub const BAYES: Venv = Venv {
    var: "BAYES_PYTHON",
    dir: "bayes-env",
};

/// pingouin, krippendorff, statsmodels, pandas (`target/stats-env`, stats-requirements.txt).
pub const STATS: Venv = Venv {
    var: "STATS_PYTHON",
    dir: "stats-env",
};

impl Venv {
    /// The Python that can import `module`: the venv's variable, else the venv itself. Under
    /// `CI` a missing interpreter or package fails the test that asks (`what`); elsewhere it
    /// returns `None` after saying why the test skips.
    pub fn python(&self, module: &str, what: &str) -> Option<PathBuf> {
        let (var, dir) = (self.var, self.dir);
        let ci = std::env::var_os("CI").is_some();
        let venv =
            Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../target/{dir}/bin/python"));
        let python = match std::env::var_os(var) {
            Some(p) => PathBuf::from(p),
            None if venv.exists() => venv,
            None if ci => panic!(
                "neither {var} nor {} is there: under CI the {what} needs the venv \
                 scripts/test makes",
                venv.display()
            ),
            None => {
                eprintln!("{what} skipped: no {var} and no target/{dir}");
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
}

/// Runs `scripts/<script>` (`golden/psignifit_golden.py`, `reference/power_reference.py`)
/// with `python` on `cases` (written to a fresh temporary file named after `tag`) and returns
/// the JSON it prints; a failing script fails the test with its stderr.
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
        .join("../scripts")
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
