//! The Python package (python/): built into a virtual environment under
//! `target/`, then its pytest suite and the Python lessons run against
//! stacks they launch with this build's `troupe`.
//!
//! The environment is `target/python-env` (made once; pip installs maturin,
//! pytest, numpy, mcap-ros2-support, mcap-protobuf-support, rosbags, websockets,
//! foxglove-schemas-protobuf and kubernetes-validate from PyPI), the package is built by `maturin
//! develop` on the workspace's own `target/` in the dev profile, so it reuses what
//! `cargo test` compiled. Where no `python3` answers the test says so and
//! passes; under CI (`CI=true`) that is a failure.

use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the workspace")
        .to_path_buf()
}

/// Runs `cmd`, panicking with its output when it fails.
fn run(what: &str, cmd: &mut Command) -> String {
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("{what}: cannot start: {e}"));
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        out.status.success(),
        "{what} failed ({}):\n{text}",
        out.status
    );
    text
}

/// `target/python-env`, made and furnished if need be (one test at a
/// time): its `python`.
pub(crate) fn environment(python3: &str) -> PathBuf {
    static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _turn = ONE_AT_A_TIME.lock().unwrap_or_else(|p| p.into_inner());
    let env = root().join("target").join("python-env");
    let python = env.join("bin").join("python");
    if !python.exists() {
        run(
            "python3 -m venv target/python-env",
            Command::new(python3).args(["-m", "venv"]).arg(&env),
        );
    }
    run(
        "pip install maturin pytest numpy mcap-ros2-support mcap-protobuf-support rosbags websockets foxglove-schemas-protobuf kubernetes-validate",
        Command::new(&python).args([
            "-m",
            "pip",
            "install",
            "--quiet",
            "--disable-pip-version-check",
            "maturin>=1.8,<2",
            "pytest",
            "numpy",
            "mcap-ros2-support",
            "mcap-protobuf-support",
            "rosbags",
            "websockets",
            "foxglove-schemas-protobuf",
            "kubernetes-validate",
        ]),
    );
    python
}

/// The `python3` to make the environment with (`$PYTHON` names another);
/// `None`, said, where none answers.
pub(crate) fn python3() -> Option<String> {
    let python3 = std::env::var("PYTHON").unwrap_or_else(|_| "python3".into());
    if Command::new(&python3).arg("--version").output().is_err() {
        troupe_tests::cannot_run(&format!("no `{python3}` here (set PYTHON to point at one)"));
        return None;
    }
    Some(python3)
}

#[test]
fn the_python_package_passes_its_tests_and_lessons() {
    let Some(python3) = python3() else { return };
    let python = environment(&python3);
    let env = python.parent().and_then(Path::parent).expect("the venv");
    let troupe = troupe_tests::troupe_bin();
    run(
        "maturin develop",
        Command::new(env.join("bin").join("maturin"))
            .args(["develop", "--quiet", "-m"])
            .arg(root().join("python").join("Cargo.toml"))
            .env("VIRTUAL_ENV", env)
            .env_remove("CARGO_TARGET_DIR"),
    );
    let out = run(
        "pytest python/tests examples/python",
        Command::new(&python)
            .args(["-m", "pytest", "-q", "-p", "no:cacheprovider"])
            .arg(root().join("python").join("tests"))
            .arg(root().join("examples").join("python"))
            .env("TROUPE_BIN", &troupe)
            .current_dir(root()),
    );
    eprintln!("{out}");
    let summary = out.lines().last().unwrap_or("");
    assert!(
        summary.contains(" passed") && !summary.contains("failed") && !summary.contains("skipped"),
        "{out}"
    );
}
