//! A real X server for the window tests: Xvfb with Mesa's software Vulkan driver, keys by
//! `xdotool`. Without the tools the tests fail under `CI` and are skipped elsewhere.
#![allow(dead_code, reason = "each test file uses its own part of the harness")]

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

/// Runs `study` with `args`, which must succeed; its standard output.
pub fn study_ok(args: &[&std::ffi::OsStr]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_study"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The window tests' stimuli: a one-second generated walk (short presentations keep the
/// tests quick) and SPIHT at 10:1 and 20:1, in `dir/stimuli/stimuli.json`.
pub fn write_walk_stimuli(dir: &Path) {
    let walk = motion::synth::WalkParams {
        duration_s: 1.0,
        // AMC files carry no rate: CMU's 120 Hz is assumed when they are read back.
        frame_rate_hz: 120.0,
        ..motion::synth::WalkParams::default()
    };
    lab::generated::walk_stimuli(dir, &walk, &["spiht"], &[10.0, 20.0]).unwrap();
}
use std::time::{Duration, Instant};

pub fn have(tool: &str) -> bool {
    Command::new("sh")
        .args(["-c", &format!("command -v {tool}")])
        .stdout(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

pub struct Xvfb {
    child: Child,
    /// `:N`.
    pub display: String,
}

impl Drop for Xvfb {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

#[allow(
    clippy::zombie_processes,
    reason = "the server is returned inside `Xvfb`, whose Drop kills and waits for it"
)]
pub fn start_xvfb() -> Xvfb {
    // A display number no other test or session uses: from the process id, and a counter
    // shared by the tests of this process (which run on parallel threads: two that checked
    // the same free number before either server made its socket would share one screen).
    static NEXT: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
    for _ in 0..20 {
        let k = NEXT.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
        let n = 90 + (std::process::id() % 400) + k * 7;
        if Path::new(&format!("/tmp/.X11-unix/X{n}")).exists() {
            continue;
        }
        let child = Command::new("Xvfb")
            // -noreset: no server reset (refusing connections) when the last client leaves.
            .args([
                &format!(":{n}"),
                "-screen",
                "0",
                "1280x720x24",
                "-nolisten",
                "tcp",
                "-noreset",
            ])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("starting Xvfb");
        let deadline = Instant::now() + Duration::from_secs(10);
        while Instant::now() < deadline {
            if Path::new(&format!("/tmp/.X11-unix/X{n}")).exists() {
                return Xvfb {
                    child,
                    display: format!(":{n}"),
                };
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }
    panic!("Xvfb did not start");
}

pub struct Env {
    /// Scratch folder (removed on drop unless `KEEP_E2E` is set).
    pub dir: PathBuf,
    /// The X server.
    pub xvfb: Xvfb,
    runtime: PathBuf,
}

impl Drop for Env {
    fn drop(&mut self) {
        if std::env::var_os("KEEP_E2E").is_some() {
            eprintln!("kept {}", self.dir.display());
            return;
        }
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

impl Env {
    /// A command that runs on this X server.
    pub fn cmd(&self, program: &str) -> Command {
        let mut c = Command::new(program);
        c.env("DISPLAY", &self.xvfb.display)
            .env("XDG_RUNTIME_DIR", &self.runtime)
            .env_remove("WAYLAND_DISPLAY")
            // Software rendering: lavapipe (it is also what wgpu picks without a GPU).
            .env("WGPU_BACKEND", "vulkan");
        c
    }

    /// Runs `xdotool` and returns its output.
    pub fn xdotool(&self, args: &[&str]) -> String {
        let out = self.cmd("xdotool").args(args).output().unwrap();
        String::from_utf8_lossy(&out.stdout).trim().to_string()
    }
}

/// A fresh folder and X server, or `None` (skip) when the tools are missing outside CI.
pub fn setup(name: &str) -> Option<Env> {
    let missing: Vec<&str> = ["Xvfb", "xdotool", "import"]
        .into_iter()
        .filter(|t| !have(t))
        .collect();
    if !missing.is_empty() {
        assert!(
            std::env::var_os("CI").is_none(),
            "under CI the window test needs {missing:?} (scripts/test installs them)"
        );
        eprintln!("skipping the window test: {missing:?} not installed");
        return None;
    }
    let dir = std::env::temp_dir().join(format!("study-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let runtime = dir.join("xdg");
    std::fs::create_dir_all(&runtime).unwrap();
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt as _;
        std::fs::set_permissions(&runtime, std::fs::Permissions::from_mode(0o700)).unwrap();
    }
    Some(Env {
        dir,
        xvfb: start_xvfb(),
        runtime,
    })
}

/// Finds the window whose name contains `title`, failing if `child` exits first.
pub fn find_window(env: &Env, child: &mut Child, title: &str) -> String {
    let deadline = Instant::now() + Duration::from_secs(120);
    while Instant::now() < deadline {
        if let Some(status) = child.try_wait().unwrap() {
            let mut err = String::new();
            if let Some(mut e) = child.stderr.take() {
                std::io::Read::read_to_string(&mut e, &mut err).unwrap();
            }
            panic!("the study process exited early ({status}): {err}");
        }
        let id = env.xdotool(&["search", "--name", title]);
        if let Some(first) = id.lines().next().filter(|l| !l.is_empty()) {
            return first.to_string();
        }
        std::thread::sleep(Duration::from_millis(200));
    }
    panic!("the window {title:?} never appeared");
}

/// How long a window test waits for one state (a screen, a rule carried out, a file) before it
/// fails. Nothing here is a timing assumption: every wait ends on the state itself, and this
/// only bounds a hang. Software rendering on a loaded two-core machine draws a frame in
/// 50-500 ms, and a window's first frames (shader compilation, the refresh measurement's 30
/// frames) take up to a minute there.
pub const STATE_WAIT: Duration = Duration::from_secs(300);

/// The script's lines on standard error (`window::test_input`) start with this.
pub const SCRIPT_PREFIX: &str = "test input:";

/// A `study` process whose window takes its keys from a test input script
/// (`STUDY_TEST_INPUT`, `window/src/test_input.rs`): no X key events and no sleeps, so
/// nothing depends on how many frames fit in a second. Its standard error and output are
/// read as they come, so a test waits for the lines the script writes.
pub struct Scripted {
    child: Child,
    stderr: std::sync::Arc<std::sync::Mutex<String>>,
    readers: Vec<std::thread::JoinHandle<()>>,
    stdout: std::sync::Arc<std::sync::Mutex<String>>,
}

impl Drop for Scripted {
    /// A failed test leaves no window behind.
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Collects `from` into `into` line by line on a thread of its own.
fn collect(
    from: impl std::io::Read + Send + 'static,
    into: &std::sync::Arc<std::sync::Mutex<String>>,
) -> std::thread::JoinHandle<()> {
    let into = std::sync::Arc::clone(into);
    std::thread::spawn(move || {
        let mut lines = std::io::BufRead::lines(std::io::BufReader::new(from));
        while let Some(Ok(line)) = lines.next() {
            let mut s = into.lock().unwrap();
            s.push_str(&line);
            s.push('\n');
        }
    })
}

impl Scripted {
    /// Runs `study ARGS` on `env`'s X server with `script` as its test input (written to
    /// `env.dir/NAME.keys`).
    pub fn spawn(env: &Env, name: &str, args: &[&std::ffi::OsStr], script: &str) -> Scripted {
        let path = env.dir.join(format!("{name}.keys"));
        std::fs::write(&path, script).unwrap();
        let mut child = env
            .cmd(env!("CARGO_BIN_EXE_study"))
            .args(args)
            .env("STUDY_TEST_INPUT", &path)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let stderr = std::sync::Arc::default();
        let stdout = std::sync::Arc::default();
        let readers = vec![
            collect(child.stderr.take().unwrap(), &stderr),
            collect(child.stdout.take().unwrap(), &stdout),
        ];
        Scripted {
            child,
            stderr,
            readers,
            stdout,
        }
    }

    /// Its standard error so far.
    pub fn stderr(&self) -> String {
        self.stderr.lock().unwrap().clone()
    }

    /// Waits until `ready()` holds, failing (with the process's standard error) if the
    /// process exits first or [`STATE_WAIT`] passes; `what` names the state in the failure.
    pub fn wait_until(&mut self, what: &str, mut ready: impl FnMut(&Scripted) -> bool) {
        let deadline = Instant::now() + STATE_WAIT;
        loop {
            if ready(self) {
                return;
            }
            if let Some(status) = self.child.try_wait().unwrap() {
                // Whatever it wrote last, then once more: the state may have come with the exit.
                std::thread::sleep(Duration::from_millis(100));
                if ready(self) {
                    return;
                }
                panic!(
                    "waiting for {what}: the study process exited ({status}):\n{}",
                    self.stderr()
                );
            }
            assert!(
                Instant::now() < deadline,
                "waiting for {what}: not after {STATE_WAIT:?}:\n{}",
                self.stderr()
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Waits for the script's line `test input: LINE` (`screen trial/open #0`, `done 2`).
    pub fn wait_line(&mut self, line: &str) {
        let want = format!("{SCRIPT_PREFIX} {line}");
        self.wait_until(&format!("{want:?}"), |s| {
            s.stderr().lines().any(|l| l == want)
        });
    }

    /// Waits for a screen whose name starts with `prefix` (`trial/open`, `trial/playing #0`).
    pub fn wait_screen(&mut self, prefix: &str) {
        let want = format!("{SCRIPT_PREFIX} screen {prefix}");
        self.wait_until(&format!("screen {prefix:?}"), |s| {
            s.stderr().lines().any(|l| l.starts_with(&want))
        });
    }

    /// Waits for the process to exit by itself; its status, standard output and error.
    pub fn wait_exit(self) -> (std::process::ExitStatus, String, String) {
        self.finish()
    }

    /// Stops the process as the experimenter's Ctrl+C does (SIGINT) and waits for it: it must
    /// exit successfully. Its standard output and error.
    pub fn interrupt(self) -> (String, String) {
        let sent = Command::new("kill")
            .args(["-INT", &self.child.id().to_string()])
            .status()
            .unwrap()
            .success();
        assert!(sent, "kill -INT");
        let (status, stdout, stderr) = self.finish();
        assert!(status.success(), "{stdout}{stderr}");
        (stdout, stderr)
    }

    /// Kills the process (SIGKILL) and waits for it.
    pub fn kill(mut self) {
        self.child.kill().unwrap();
        let _ = self.finish();
    }

    /// Waits for the exit (bounded by [`STATE_WAIT`]) and for the readers.
    fn finish(mut self) -> (std::process::ExitStatus, String, String) {
        let deadline = Instant::now() + STATE_WAIT;
        let status = loop {
            if let Some(s) = self.child.try_wait().unwrap() {
                break s;
            }
            if Instant::now() >= deadline {
                let _ = self.child.kill();
                panic!("the study process did not exit:\n{}", self.stderr());
            }
            std::thread::sleep(Duration::from_millis(50));
        };
        for r in self.readers.drain(..) {
            r.join().unwrap();
        }
        let stdout = self.stdout.lock().unwrap().clone();
        (status, stdout, self.stderr())
    }
}

/// Bare Xvfb has no window manager: the window gets the keyboard focus before every press
/// (until it is mapped a focus request is lost), then plain `xdotool key` reaches it
/// (`key --window` events were seen to be dropped).
pub fn press(env: &Env, wid: &str, keys: &[&str]) {
    env.xdotool(&["windowfocus", "--sync", wid]);
    let mut args = vec!["key"];
    args.extend_from_slice(keys);
    env.xdotool(&args);
}

/// Stops `child` (a `study run`) as the experimenter's Ctrl+C does, with SIGINT, and waits
/// for it: it must exit successfully. Its standard output and error.
pub fn interrupt(child: Child) -> (String, String) {
    let sent = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap()
        .success();
    assert!(sent, "kill -INT");
    let out = child.wait_with_output().unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    );
    assert!(out.status.success(), "{stdout}{stderr}");
    (stdout, stderr)
}

/// A screenshot of the whole X screen into `path` (ImageMagick's `import`).
pub fn screenshot(env: &Env, path: &Path) {
    let ok = env
        .cmd("import")
        .args(["-window", "root"])
        .arg(path)
        .status()
        .unwrap()
        .success();
    assert!(ok, "import could not take a screenshot");
}

/// Where a figure's joints are in an image, pixels ([`Rgb::orange_figures`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Figure {
    pub left: usize,
    pub right: usize,
    pub top: usize,
    pub bottom: usize,
}

/// An image read as 8-bit colour (ImageMagick may write 16-bit, paletted or, for a grey-only
/// screen, grayscale PNGs).
pub struct Rgb {
    pub width: usize,
    pub height: usize,
    line: usize,
    channels: usize,
    buf: Vec<u8>,
}

impl Rgb {
    pub fn read(path: &Path) -> Rgb {
        let mut dec =
            png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
        dec.set_transformations(png::Transformations::normalize_to_color8());
        let mut reader = dec.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        Rgb {
            width: info.width as usize,
            height: info.height as usize,
            line: info.line_size,
            channels: info.line_size / info.width as usize,
            buf,
        }
    }

    /// The colour at (x, y) (grey repeated for a grayscale image).
    pub fn pixel(&self, x: usize, y: usize) -> [u8; 3] {
        let i = y * self.line + x * self.channels;
        if self.channels < 3 {
            return [self.buf[i]; 3];
        }
        [self.buf[i], self.buf[i + 1], self.buf[i + 2]]
    }

    /// The figures of the area `xs` × `ys`: the columns holding joint-orange pixels,
    /// grouped where fewer than `gap` empty columns part them; each group's left and right
    /// column and top and bottom row, left to right.
    pub fn orange_figures(
        &self,
        xs: std::ops::Range<usize>,
        ys: std::ops::Range<usize>,
        gap: usize,
    ) -> Vec<Figure> {
        let mut out: Vec<Figure> = Vec::new();
        for x in xs {
            let mut rows = ys.clone().filter(|&y| self.is_orange(x, y));
            let Some(top) = rows.next() else { continue };
            let bottom = rows.next_back().unwrap_or(top);
            match out.last_mut() {
                Some(f) if x <= f.right + gap => {
                    f.right = x;
                    f.top = f.top.min(top);
                    f.bottom = f.bottom.max(bottom);
                }
                _ => out.push(Figure {
                    left: x,
                    right: x,
                    top,
                    bottom,
                }),
            }
        }
        out
    }

    /// Whether the pixel at (x, y) is the joints' orange (red well above blue); never in a
    /// grayscale image.
    pub fn is_orange(&self, x: usize, y: usize) -> bool {
        if self.channels < 3 {
            return false;
        }
        let i = y * self.line + x * self.channels;
        i32::from(self.buf[i]) - i32::from(self.buf[i + 2]) > 60
    }
}
