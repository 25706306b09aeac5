//! `troupe view` against a launched stack: its JSON says what the
//! simulator and `troupe list` say, its stream carries the robots' poses and
//! readings, and a real browser (Debian's chromium, headless) draws the
//! world where the simulator has it.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::time::Instant;

use serde_json::Value;
use troupe_tests::{strings, Proc, DEADLINE};

/// A wall 0.2 m thick across x = 2 m, a red robot at the origin facing +x
/// with a 90-beam, 180° ranger (blue), and no controller: it stays put.
const WORLD: &str = r#"
resolution 0.02
model ( name "wall" pose [2 0 0 0] size [0.2 4 1] color "black" )
position
(
  name "r0" pose [0 0 0 0] size [0.4 0.4 0.3] color "red"
  ranger ( sensor ( samples 90 fov 180 range [0 5] ) size [0.1 0.1 0.1] color "blue" )
)
"#;

const CFG: &str = r#"
driver ( name "stage" provides [ "simulation:0" ] plugin "stageplugin" worldfile "view.world" )
driver ( name "stage" provides [ "position2d:0" "ranger:0" ] model "r0" )
"#;

/// GET `path` from `base` (`http://127.0.0.1:PORT/`): the status line's
/// code and the body.
fn get(base: &str, path: &str) -> (u32, String) {
    let host = base.trim_start_matches("http://").trim_end_matches('/');
    let mut s = TcpStream::connect(host).unwrap();
    s.set_read_timeout(Some(DEADLINE)).unwrap();
    write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    // The head, then as many bytes as it says (a server may keep the
    // connection open), or to the end.
    let mut r = BufReader::new(s);
    let mut head = Vec::new();
    loop {
        let mut line = String::new();
        r.read_line(&mut line).unwrap();
        if line.trim().is_empty() {
            break;
        }
        head.push(line);
    }
    let code = head[0].split_whitespace().nth(1).unwrap().parse().unwrap();
    let length = head.iter().find_map(|h| {
        let (k, v) = h.split_once(':')?;
        k.eq_ignore_ascii_case("content-length")
            .then(|| v.trim().parse::<usize>().ok())?
    });
    let mut body = Vec::new();
    match length {
        Some(n) => {
            body.resize(n, 0);
            r.read_exact(&mut body).unwrap();
        }
        None => {
            r.read_to_end(&mut body).unwrap();
        }
    }
    (code, String::from_utf8(body).unwrap())
}

pub(crate) fn json(base: &str, path: &str) -> Value {
    let (code, body) = get(base, path);
    assert_eq!(code, 200, "{path}: {body}");
    serde_json::from_str(&body).unwrap()
}

/// A stack launched from `cfg` in a namespace of its own, with `troupe
/// view` on a free port beside it.
struct Viewed {
    launcher: Proc,
    view: Proc,
    ns: String,
    router: String,
    /// `http://127.0.0.1:PORT/`.
    base: String,
}

impl Viewed {
    fn launch(name: &str, cfg: &Path, extra: &[&str]) -> Viewed {
        let ns = troupe_tests::unique_namespace(name);
        let mut launcher = troupe_tests::launch(&ns, cfg, extra);
        let (router, _) = troupe_tests::launch_ports(&mut launcher);
        let mut view = Proc::troupe(
            "view",
            &Viewed::args(&ns, &router, &["view", "--port", "0"]),
        );
        let line = view.first_line();
        let base = line
            .trim()
            .strip_prefix("troupe view: ")
            .expect("the view's address")
            .to_owned();
        Viewed {
            launcher,
            view,
            ns,
            router,
            base,
        }
    }

    /// `troupe` arguments for a tool on this stack's network.
    fn args(ns: &str, router: &str, rest: &[&str]) -> Vec<String> {
        let mut a = strings(&["--namespace", ns, "--connect", router]);
        a.extend(strings(rest));
        a
    }

    /// Stops the view and the stack, each cleanly.
    fn stop(mut self) {
        assert!(self.view.terminate().success(), "{}", self.view.stderr());
        assert!(
            self.launcher.terminate().success(),
            "{}",
            self.launcher.stderr()
        );
    }
}

/// POSTs `body` to the view's /api/command: the status code and the text.
pub(crate) fn post(base: &str, body: &Value) -> (u32, String) {
    post_to(base, "/api/command", body)
}

/// POSTs `body` to `path` of the view: the status code and the text.
fn post_to(base: &str, path: &str, body: &Value) -> (u32, String) {
    let host = base.trim_start_matches("http://").trim_end_matches('/');
    let mut s = TcpStream::connect(host).unwrap();
    s.set_read_timeout(Some(DEADLINE)).unwrap();
    let body = body.to_string();
    write!(
        s,
        "POST {path} HTTP/1.0\r\nHost: {host}\r\nContent-Type: application/json\r\nContent-Length: {}\r\n\r\n{body}",
        body.len()
    )
    .unwrap();
    let mut all = String::new();
    s.read_to_string(&mut all).unwrap();
    let (head, text) = all.split_once("\r\n\r\n").unwrap();
    (
        head.split_whitespace().nth(1).unwrap().parse().unwrap(),
        text.to_owned(),
    )
}

/// Asserts that the view's device list at `path` is what `troupe list`
/// prints in namespace `ns` (robot, device and driver), `n` devices.
fn lists_as_troupe_list(base: &str, path: &str, ns: &str, router: &str, n: usize) {
    let (ok, out, err) = troupe_tests::troupe_output(&Viewed::args(
        ns,
        router,
        &["list", "--json", "--wait", "2"],
    ));
    assert!(ok.success(), "{err}");
    let key = |v: &Value| format!("{} {} {}", v["robot"], v["device"], v["driver"]);
    let mut want: Vec<String> = out
        .lines()
        .map(|l| key(&serde_json::from_str(l).unwrap()))
        .collect();
    let mut got: Vec<String> = json(base, path)
        .as_array()
        .unwrap()
        .iter()
        .map(key)
        .collect();
    want.sort();
    got.sort();
    assert_eq!(got, want, "{path} in {ns}");
    assert_eq!(got.len(), n);
}

/// The first frame of the stream that `done` accepts.
fn frame_where(base: &str, done: impl Fn(&Value) -> bool) -> Value {
    frame_of(base, "/api/stream", done)
}

/// The first frame of the stream at `path` that `done` accepts.
fn frame_of(base: &str, path: &str, done: impl Fn(&Value) -> bool) -> Value {
    let host = base.trim_start_matches("http://").trim_end_matches('/');
    let mut s = TcpStream::connect(host).unwrap();
    s.set_read_timeout(Some(DEADLINE)).unwrap();
    write!(s, "GET {path} HTTP/1.1\r\nHost: {host}\r\n\r\n").unwrap();
    let deadline = Instant::now() + DEADLINE;
    let mut last = Value::Null;
    for line in BufReader::new(s).lines() {
        assert!(
            Instant::now() < deadline,
            "no frame as wanted; the last: {last}"
        );
        let line = line.unwrap();
        if let Some(data) = line.strip_prefix("data:") {
            last = serde_json::from_str(data.trim()).unwrap();
            if done(&last) {
                return last;
            }
        }
    }
    panic!("the stream ended; the last frame: {last}");
}

#[test]
fn the_view_draws_the_world_where_the_simulator_has_it() {
    let dir = std::env::temp_dir().join(format!("troupe-view-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("view.world"), WORLD).unwrap();
    std::fs::write(dir.join("view.cfg"), CFG).unwrap();
    let stack = Viewed::launch("view", &dir.join("view.cfg"), &[]);
    let base = stack.base.clone();

    // The stream: r0 where the world file puts it, its ranger's middle
    // beams on the wall's face, 1.9 m ahead. (Each device's first reading
    // comes on its own: the frame waited for has all that is read of it.)
    let f = frame_where(&base, |f| {
        f["devices"] == 3
            && f["readings"]["6665:ranger:0"].is_object()
            && f["readings"]["6665:position2d:0"].is_object()
            && f["poses"]["6665:simulation:0"].is_object()
            && f["worlds"] == 1
    });
    let world = json(&base, "/api/world");
    // The view watches its session's namespace, and may command.
    assert_eq!(world["namespace"], stack.ns.as_str());
    assert_eq!(world["looking_only"], Value::Null);
    let w = &world["worlds"][0];
    assert_eq!(w["simulation"], "6665:simulation:0");
    let id = |name: &str| {
        w["models"]
            .as_array()
            .unwrap()
            .iter()
            .position(|m| m["name"] == name)
            .unwrap_or_else(|| panic!("no {name} in {w}"))
    };
    let (r0, wall) = (id("r0"), id("wall"));
    assert_eq!(w["models"][r0]["color"], "#ff0000");
    assert_eq!(w["models"][r0]["moves"], true);
    assert_eq!(w["models"][wall]["moves"], false);
    assert_eq!(
        w["models"][wall]["pose"],
        serde_json::json!([2.0, 0.0, 0.0])
    );
    let pose = &f["poses"]["6665:simulation:0"][r0.to_string()];
    assert_eq!(pose, &serde_json::json!([0.0, 0.0, 0.0]), "{f}");
    // Each simulator's time comes with its poses (the page glides models
    // from one set to the next).
    assert_eq!(f["times"]["6665:simulation:0"], f["time"], "{f}");
    let ranges = f["readings"]["6665:ranger:0"]["ranges"].as_array().unwrap();
    assert_eq!(ranges.len(), 90);
    for k in [44, 45] {
        let r = ranges[k].as_f64().unwrap();
        assert!((r - 1.9).abs() < 0.03, "beam {k}: {r} m");
    }
    assert_eq!(f["readings"]["6665:position2d:0"]["kind"], "position2d");
    // Each device's rate, as `troupe hz` would count it: the ranger updates
    // at Stage's 10 Hz (the world runs in real time).
    // (The first reckoning may cover part of a second: the rate is waited
    // for, and the stream's deadline fails the test if it never comes.)
    frame_where(&base, |f| {
        f["rates"]["6665:ranger:0"]
            .as_f64()
            .is_some_and(|r| (8.0..12.0).contains(&r))
    });
    let ranger = w["devices"]
        .as_array()
        .unwrap()
        .iter()
        .find(|d| d["device"] == "6665:ranger:0")
        .unwrap();
    assert_eq!(ranger["sensors"][0]["samples"], 90);

    // The device list is `troupe list`'s.
    lists_as_troupe_list(&base, "/api/devices", &stack.ns, &stack.router, 3);

    // The page, in a real browser, at 50 pixels a metre around the origin.
    let (code, html) = get(&base, "/");
    assert_eq!(code, 200);
    assert!(html.contains("view.js"));
    if let Some(browser) = chromium() {
        screenshot_shows_the_world(&browser, &base, &dir);
    }

    // A page's frames carry what it shows: a box far from r0 gets no ray
    // of its ranger and no pose of it; a box around r0 gets both.
    let view_box = |page: &str, b: [f64; 4]| {
        let (code, text) = post_to(
            &base,
            "/api/view",
            &serde_json::json!({ "page": page, "box": b }),
        );
        assert_eq!(code, 200, "{text}");
    };
    view_box("far", [20.0, 20.0, 30.0, 30.0]);
    let far = frame_of(&base, "/api/stream?page=far", |f| {
        f["poses"]["6665:simulation:0"].is_object()
    });
    assert!(far["readings"]["6665:ranger:0"].is_null(), "{far}");
    assert!(
        far["poses"]["6665:simulation:0"][r0.to_string()].is_null(),
        "{far}"
    );
    view_box("near", [-1.0, -1.0, 1.0, 1.0]);
    let near = frame_of(&base, "/api/stream?page=near", |f| {
        f["poses"]["6665:simulation:0"].is_object()
    });
    assert!(near["readings"]["6665:ranger:0"].is_object(), "{near}");
    assert!(
        near["poses"]["6665:simulation:0"][r0.to_string()].is_array(),
        "{near}"
    );

    // Teleop: r0 drives forward, then stops.
    assert_eq!(
        post(
            &base,
            &serde_json::json!({"device": "6665:position2d:0", "vel": [0.3, 0.0, 0.0]})
        )
        .0,
        200
    );
    let key = r0.to_string();
    frame_where(&base, |f| {
        f["poses"]["6665:simulation:0"][&key][0]
            .as_f64()
            .is_some_and(|x| x > 0.1)
    });
    assert_eq!(
        post(
            &base,
            &serde_json::json!({"device": "6665:position2d:0", "vel": [0.0, 0.0, 0.0]})
        )
        .0,
        200
    );
    // Orders that make no sense are refused and say why.
    let (code, why) = post(
        &base,
        &serde_json::json!({"device": "6665:ranger:0", "goal": [1.0, 0.0, 0.0]}),
    );
    assert_eq!(code, 400);
    assert!(why.contains("a planner takes a goal"), "{why}");
    // A request no driver answers: 502, saying so.
    let (code, why) = post(
        &base,
        &serde_json::json!({"device": "6665:localize:7", "pose": [1.0, 0.0, 0.0]}),
    );
    assert_eq!(code, 502, "{why}");

    stack.stop();
    let _ = std::fs::remove_dir_all(&dir);
}

/// Debian's chromium, if installed; under CI=true it must be.
fn chromium() -> Option<std::path::PathBuf> {
    let found = ["/usr/bin/chromium", "/usr/bin/chromium-browser"]
        .iter()
        .map(Path::new)
        .find(|p| p.exists())
        .map(Path::to_path_buf);
    if found.is_none() {
        troupe_tests::cannot_run("no chromium for the browser check (.ci/run installs it)");
    }
    found
}

/// A headless Chromium screenshot of `url` in a `w` × `h` window, after
/// the page has loaded (`?still` pages open no stream, and the time
/// budget lets them load).
fn screenshot(browser: &Path, url: &str, (w, h): (u32, u32), dir: &Path) -> image::RgbImage {
    let shot = dir.join("view.png");
    let status = std::process::Command::new(browser)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--hide-scrollbars",
        ])
        .arg(format!(
            "--user-data-dir={}",
            dir.join("chromium").display()
        ))
        .arg(format!("--window-size={w},{h}"))
        .arg(format!("--screenshot={}", shot.display()))
        .arg("--virtual-time-budget=5000")
        .arg(url)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status()
        .unwrap();
    assert!(status.success(), "chromium: {status}");
    let img = image::open(&shot).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (w, h));
    img
}

fn screenshot_shows_the_world(browser: &Path, base: &str, dir: &Path) {
    // The canvas is the window less the 261-pixel side panel: 639 × 600,
    // its centre (319.5, 300) the world's origin.
    let url = format!("{base}?still&x=0&y=0&scale=50&device=6665:ranger:0");
    let img = screenshot(browser, &url, (900, 600), dir);
    let px = |x: f64, y: f64| {
        let (sx, sy) = (319.5 + x * 50.0, 300.0 - y * 50.0);
        img.get_pixel(sx as u32, sy as u32).0
    };
    // r0's body behind its ranger (no rays there): red.
    assert_eq!(px(-0.15, 0.0), [255, 0, 0], "r0's body");
    // Inside the wall, beyond the rays' ends: black.
    assert_eq!(px(2.0, 1.0), [0, 0, 0], "the wall");
    // Open floor behind the robot: white.
    assert_eq!(px(-3.0, 3.0), [255, 255, 255], "the floor");
    // The ranger's panel (as playerv's): its ranges plotted in blue, in
    // the side panel.
    let plotted = (640..900)
        .flat_map(|x| (0..600).map(move |y| (x, y)))
        .filter(|&(x, y)| {
            let [r, g, b] = img.get_pixel(x, y).0;
            b > 150 && r < 60 && g < 120
        })
        .count();
    assert!(plotted > 50, "{plotted} plot pixels in the side panel");
}

/// The navigation stack of worlds/nav.cfg under the view: amcl's estimate
/// and the planner's state reach the page; in a real browser (driven over
/// the DevTools protocol, mouse events as a person's) a goal pressed and
/// dragged on the map (rviz's "2D Goal") takes r0 there, and a pose set
/// the same way ("2D Pose Estimate") moves amcl's estimate. Without
/// chromium (outside CI) the same orders go through the page's HTTP API.
#[test]
fn the_view_gives_goals_and_sets_poses() {
    let cfg = Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds/nav.cfg");
    let stack = Viewed::launch("viewnav", &cfg, &["--speedup", "4"]);
    let (base, router, ns) = (stack.base.clone(), stack.router.clone(), stack.ns.clone());
    let f = frame_where(&base, |f| {
        f["poses"]["6665:simulation:0"]
            .as_object()
            .is_some_and(|p| !p.is_empty())
            && f["nav"]["6665:localize:0"]["hypoths"].is_array()
            && f["nav"]["6665:planner:0"]["kind"] == "planner"
            && f["worlds"] == 1
    });
    let world = json(&base, "/api/world");
    let r0 = world["worlds"][0]["models"]
        .as_array()
        .unwrap()
        .iter()
        .position(|m| m["name"] == "r0")
        .unwrap()
        .to_string();
    let at = |f: &Value| {
        let p = &f["poses"]["6665:simulation:0"][&r0];
        (
            p[0].as_f64().unwrap_or(f64::NAN),
            p[1].as_f64().unwrap_or(f64::NAN),
        )
    };
    let start = at(&f);
    assert!(
        (start.0 + 6.0).hypot(start.1 + 6.0) < 0.1,
        "r0 starts at {start:?}"
    );

    // A goal in the room's east end: the planner takes it and r0 gets there.
    let goal = (4.0, -6.0);
    // In a real browser: pick "give a goal", press on the goal, drag east.
    let browser = chromium().map(|b| Page::open(&b, &format!("{base}?x=0&y=0&scale=30")));
    match &browser {
        Some(page) => {
            page.click_element("input[value=goal]");
            page.drag(page.at(goal), page.at((goal.0 + 1.0, goal.1)));
        }
        None => {
            let (code, text) = post(
                &base,
                &serde_json::json!({"device": "6665:planner:0", "goal": [goal.0, goal.1, 0.0]}),
            );
            assert_eq!(code, 200, "{text}");
        }
    }
    // The page with the path and amcl's estimate on it: the README's
    // picture.
    frame_where(&base, |f| {
        let p = &f["nav"]["6665:planner:0"];
        let h = &f["nav"]["6665:localize:0"]["hypoths"];
        p["valid"] == true
            && p["waypoints"].as_array().is_some_and(|w| w.len() > 1)
            && h.as_array().is_some_and(|h| !h.is_empty())
    });
    // The path the page draws runs from r0 through the waypoint it drives
    // to, and no stretch of it crosses a wall of the map.
    let f = frame_where(&base, |f| {
        f["nav"]["6665:planner:0"]["path"]
            .as_array()
            .is_some_and(|p| p.len() > 1)
    });
    let path: Vec<[f64; 3]> =
        serde_json::from_value(f["nav"]["6665:planner:0"]["path"].clone()).unwrap();
    let mut map = troupe_client::MapProxy::new(
        &troupe_client::Client::with_session(troupe_tests::client_at(&router, &ns), 6665),
        0,
    );
    map.request_map().unwrap();
    let res = map.resolution();
    for leg in path.windows(2) {
        let (a, b) = (leg[0], leg[1]);
        let steps = ((b[0] - a[0]).hypot(b[1] - a[1]) / (res / 2.0))
            .ceil()
            .max(1.0) as u32;
        for k in 0..=steps {
            let t = f64::from(k) / f64::from(steps);
            let (x, y) = (a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]));
            let i = ((x - map.origin().x) / res).floor() as u32;
            let j = ((y - map.origin().y) / res).floor() as u32;
            assert_ne!(
                map.cell(i, j),
                Some(1),
                "the drawn path {path:?} crosses a wall at ({x:.2}, {y:.2})"
            );
        }
    }
    if let Some(browser) = chromium() {
        readme_picture(&browser, &base);
    }
    let f = frame_where(&base, |f| {
        let (x, y) = at(f);
        (x - goal.0).hypot(y - goal.1) < 0.5
    });
    // Where it was pressed, to the pixel (1/30 m), facing the drag.
    let g: Vec<f64> = serde_json::from_value(f["nav"]["6665:planner:0"]["goal"].clone()).unwrap();
    assert!(
        (g[0] - goal.0).abs() < 0.05 && (g[1] - goal.1).abs() < 0.05 && g[2].abs() < 0.05,
        "goal {g:?}"
    );

    // A pose a metre off the truth: amcl's estimate goes there. (Every
    // estimate amcl publishes is watched, from before the drag: amcl may
    // settle back on the truth within a frame of the page's stream.)
    let (x, y) = at(&f);
    let set = (x, y + 1.0);
    let (tx, estimates) = std::sync::mpsc::channel();
    let session = troupe_tests::client_at(&router, &ns);
    let _watch = {
        use troupe_node::zenoh::Wait;
        let dev = troupe_msgs::Device::new(6665, troupe_msgs::Interface::Localize, 0);
        session
            .declare_subscriber(troupe_msgs::keys::data(&dev))
            .callback(move |s| {
                if let Ok(h) =
                    troupe_msgs::decode::<troupe_msgs::localize::Hypoths>(&s.payload().to_bytes())
                {
                    if let Some(best) = h.msg.hypoths.first() {
                        let _ = tx.send((best.mean.x, best.mean.y));
                    }
                }
            })
            .wait()
            .unwrap()
    };
    // "set the pose": press where r0 is said to be, drag east.
    match &browser {
        Some(page) => {
            page.click_element("input[value=pose]");
            page.drag(page.at(set), page.at((set.0 + 1.0, set.1)));
        }
        None => {
            let (code, text) = post(
                &base,
                &serde_json::json!({"device": "6665:localize:0", "pose": [set.0, set.1, 0.0]}),
            );
            assert_eq!(code, 200, "{text}");
        }
    }
    let deadline = Instant::now() + DEADLINE;
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        let (mx, my) = estimates
            .recv_timeout(left)
            .expect("amcl's estimate never went to the pose set");
        if (mx - set.0).hypot(my - set.1) < 0.25 {
            break;
        }
    }

    drop(browser);
    stack.stop();
}

/// Without a simulator, the view draws the map devices (worlds/map.cfg:
/// mapfile and its two filters): each one's picture is its grid, free
/// cells white and occupied black, north up.
#[test]
fn the_view_draws_map_devices() {
    use troupe_client::{Client, MapProxy};
    let cfg = Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds/map.cfg");
    let stack = Viewed::launch("viewmap", &cfg, &[]);
    let (base, router, ns) = (stack.base.clone(), stack.router.clone(), stack.ns.clone());
    frame_where(&base, |f| f["maps"] == 3);
    let world = json(&base, "/api/world");
    let maps = world["maps"].as_array().unwrap();
    let names: Vec<&str> = maps.iter().map(|m| m["device"].as_str().unwrap()).collect();
    assert_eq!(names, ["6665:map:0", "6665:map:1", "6665:map:2"]);

    // map:0's picture against its cells, as a Player client reads them.
    let client = Client::with_session(troupe_tests::client_at(&router, &ns), 6665);
    let mut map = MapProxy::new(&client, 0);
    map.request_map().unwrap();
    let (w, h) = (map.width(), map.height());
    assert_eq!(
        (maps[0]["width"].as_u64(), maps[0]["height"].as_u64()),
        (Some(w.into()), Some(h.into()))
    );
    let host = base.trim_start_matches("http://").trim_end_matches('/');
    let mut s = TcpStream::connect(host).unwrap();
    s.set_read_timeout(Some(DEADLINE)).unwrap();
    write!(
        s,
        "GET /api/map/6665:map:0 HTTP/1.0\r\nHost: {host}\r\n\r\n"
    )
    .unwrap();
    let mut all = Vec::new();
    s.read_to_end(&mut all).unwrap();
    let at = all.windows(4).position(|b| b == b"\r\n\r\n").unwrap() + 4;
    assert!(String::from_utf8_lossy(&all[..at]).contains("image/png"));
    let img = image::load_from_memory(&all[at..]).unwrap().to_luma8();
    assert_eq!(img.dimensions(), (w, h));
    let (mut free, mut occupied) = (0, 0);
    for j in 0..h {
        for i in 0..w {
            let want = match map.cell(i, j) {
                Some(c) if c < 0 => 255,
                Some(0) | None => 200,
                Some(_) => 0,
            };
            assert_eq!(img.get_pixel(i, h - 1 - j).0[0], want, "cell ({i}, {j})");
            free += usize::from(want == 255);
            occupied += usize::from(want == 0);
        }
    }
    assert!(free > 0 && occupied > 0, "{free} free, {occupied} occupied");
    let (code, _) = get(&base, "/api/map/6665:map:9");
    assert_eq!(code, 404);

    // A page left open (its stream of frames): the view still stops at
    // once and cleanly (it ignored SIGTERM until killed, waiting on it).
    let mut page = TcpStream::connect(host).unwrap();
    page.set_read_timeout(Some(DEADLINE)).unwrap();
    write!(page, "GET /api/stream HTTP/1.0\r\nHost: {host}\r\n\r\n").unwrap();
    let mut first = [0u8; 256];
    assert!(
        page.read(&mut first).unwrap() > 0,
        "the stream's first bytes"
    );
    stack.stop();
    drop(page);
}

/// Two stacks in two namespaces on one network. `launch --view` serves the
/// first one's view beside it; `troupe view --namespaces A,B` watches both:
/// each namespace's world, devices, frames and commands are its own, and
/// the page offers a choice of the two.
#[test]
fn one_view_watches_several_namespaces() {
    let dir = std::env::temp_dir().join(format!("troupe-viewns-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("view.world"), WORLD).unwrap();
    std::fs::write(dir.join("view.cfg"), CFG).unwrap();
    // B's r0 stands a metre off A's, in a world of its own.
    std::fs::create_dir_all(dir.join("b")).unwrap();
    std::fs::write(
        dir.join("b/view.world"),
        WORLD.replace(r#"name "r0" pose [0 0 0 0]"#, r#"name "r0" pose [1 1 0 0]"#),
    )
    .unwrap();
    std::fs::write(dir.join("b/view.cfg"), CFG).unwrap();
    let (a, b) = (
        troupe_tests::unique_namespace("viewa"),
        troupe_tests::unique_namespace("viewb"),
    );

    // A, with its view served by the launcher; B joins A's router.
    let mut launcher_a = troupe_tests::launch(&a, &dir.join("view.cfg"), &["--view=127.0.0.1:0"]);
    let lines = launcher_a.lines();
    let (mut router, mut own_view) = (None, None);
    let deadline = Instant::now() + DEADLINE;
    while router.is_none() || own_view.is_none() {
        let left = deadline.saturating_duration_since(Instant::now());
        let line = lines
            .recv_timeout(left)
            .expect("the launcher's router and view lines");
        if let Some(rest) = line.strip_prefix("troupe launch: router listening on ") {
            router = rest.split_whitespace().next().map(str::to_owned);
        } else if let Some(rest) = line.strip_prefix("troupe view: ") {
            own_view = Some(rest.trim().to_owned());
        }
    }
    let (router, own_view) = (router.unwrap(), own_view.unwrap());
    let mut launcher_b = Proc::troupe(
        "launch b",
        &Viewed::args(
            &b,
            &router,
            &[
                "launch",
                dir.join("b/view.cfg").to_str().unwrap(),
                "--no-bridge",
            ],
        ),
    );
    let mut view = Proc::troupe(
        "view",
        &strings(&[
            "--connect",
            &router,
            "view",
            "--port",
            "0",
            "--namespaces",
            &format!("{a},{b}"),
        ]),
    );
    let base = view
        .first_line()
        .trim()
        .strip_prefix("troupe view: ")
        .expect("the view's address")
        .to_owned();

    // launch --view watches the launch's namespace only.
    let own = json(&own_view, "/api/world");
    assert_eq!(own["namespace"], a.as_str());
    assert_eq!(own["namespaces"], serde_json::json!([a]));

    // Each namespace's frames carry its own r0: A's at the origin, B's a
    // metre off.
    let r0_at = |ns: usize, x: &dyn Fn(f64) -> bool| {
        frame_of(&base, &format!("/api/stream?ns={ns}"), |f| {
            f["worlds"] == 1
                && f["poses"]["6665:simulation:0"]["1"][0]
                    .as_f64()
                    .is_some_and(x)
        })
    };
    r0_at(0, &|x| x == 0.0);
    r0_at(1, &|x| x == 1.0);
    for (k, ns) in [&a, &b].into_iter().enumerate() {
        let world = json(&base, &format!("/api/world?ns={k}"));
        assert_eq!(world["namespace"], ns.as_str());
        assert_eq!(world["namespaces"], serde_json::json!([a, b]));
        assert_eq!(world["worlds"][0]["models"][1]["name"], "r0");
        // Its devices are `troupe list`'s in that namespace.
        lists_as_troupe_list(&base, &format!("/api/devices?ns={k}"), ns, &router, 3);
    }
    let (code, why) = get(&base, "/api/world?ns=2");
    assert_eq!(code, 404);
    assert!(why.contains("no namespace 2"), "{why}");

    // A command goes to the namespace it names: B's r0 drives, A's stays.
    let (code, text) = post(
        &base,
        &serde_json::json!({"ns": 1, "device": "6665:position2d:0", "vel": [0.3, 0.0, 0.0]}),
    );
    assert_eq!(code, 200, "{text}");
    r0_at(1, &|x| x > 1.1);
    assert_eq!(
        post(
            &base,
            &serde_json::json!({"ns": 1, "device": "6665:position2d:0", "vel": [0.0, 0.0, 0.0]})
        )
        .0,
        200
    );
    let a_now = json(&base, "/api/frame?ns=0");
    assert_eq!(
        a_now["poses"]["6665:simulation:0"]["1"],
        serde_json::json!([0.0, 0.0, 0.0]),
        "{a_now}"
    );

    // In a browser: the page offers both namespaces and lists the chosen
    // one's devices; ?ns=1 shows B.
    if let Some(browser) = chromium() {
        for (k, ns) in [&a, &b].into_iter().enumerate() {
            let page = Page::open(&browser, &format!("{base}?ns={k}&x=0&y=0&scale=50"));
            let offered = page.eval(
                "JSON.stringify([document.getElementById('spaces').hidden, \
                 [...document.getElementById('space').options].map(o => o.text), \
                 document.getElementById('space').value, \
                 document.getElementById('namespace').textContent, \
                 document.getElementById('devices').rows.length])",
            );
            assert_eq!(
                serde_json::from_str::<Value>(&offered).unwrap(),
                serde_json::json!([false, [a, b], k.to_string(), format!(" in {ns}"), 3]),
            );
        }
    }

    assert!(view.terminate().success(), "{}", view.stderr());
    assert!(launcher_b.terminate().success(), "{}", launcher_b.stderr());
    // The launcher stops its view too, and says it stopped cleanly.
    assert!(launcher_a.terminate().success(), "{}", launcher_a.stderr());
    assert!(
        TcpStream::connect(own_view.trim_start_matches("http://").trim_end_matches('/')).is_err(),
        "launch --view's page is still served"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A page of headless Chromium, driven over the DevTools protocol: mouse
/// presses, drags and clicks as a person's, at page coordinates.
struct Page {
    browser: std::process::Child,
    ws: std::cell::RefCell<tungstenite::WebSocket<tungstenite::stream::MaybeTlsStream<TcpStream>>>,
    next: std::cell::Cell<u64>,
    /// The view's fixed centre and scale, and the canvas's size.
    view: (f64, f64, f64),
    canvas: (f64, f64),
    _dir: tempdir::Dir,
}

mod tempdir {
    /// A directory removed when dropped.
    pub struct Dir(pub std::path::PathBuf);
    impl Drop for Dir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

impl Page {
    /// Opens `url` (with ?x=&y=&scale= fixing the view) in a 1000 × 650
    /// window and waits until the page has drawn.
    fn open(browser: &Path, url: &str) -> Page {
        let dir = tempdir::Dir(std::env::temp_dir().join(troupe_tests::unique_namespace("cdp")));
        let mut child = std::process::Command::new(browser)
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--hide-scrollbars",
            ])
            .arg("--remote-debugging-port=0")
            .arg(format!("--user-data-dir={}", dir.0.display()))
            .arg("--window-size=1000,650")
            .arg(url)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        // "DevTools listening on ws://127.0.0.1:PORT/devtools/browser/…"
        let err = child.stderr.take().unwrap();
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(err).lines().map_while(Result::ok) {
                if let Some(at) = line.strip_prefix("DevTools listening on ") {
                    let _ = tx.send(at.to_owned());
                }
            }
        });
        let browser_ws = rx
            .recv_timeout(DEADLINE)
            .expect("chromium's DevTools address");
        let host = browser_ws
            .trim_start_matches("ws://")
            .split('/')
            .next()
            .unwrap()
            .to_owned();
        let list: Value =
            serde_json::from_str(&get(&format!("http://{host}/"), "/json/list").1).unwrap();
        let page = list
            .as_array()
            .unwrap()
            .iter()
            .find(|t| t["type"] == "page")
            .expect("a page target");
        let (ws, _) = tungstenite::connect(page["webSocketDebuggerUrl"].as_str().unwrap()).unwrap();
        let q: std::collections::HashMap<String, f64> = url
            .split_once('?')
            .map(|(_, q)| q)
            .unwrap_or("")
            .split('&')
            .filter_map(|kv| kv.split_once('='))
            .filter_map(|(k, v)| Some((k.to_owned(), v.parse().ok()?)))
            .collect();
        let mut p = Page {
            browser: child,
            ws: std::cell::RefCell::new(ws),
            next: std::cell::Cell::new(1),
            view: (q["x"], q["y"], q["scale"]),
            canvas: (0.0, 0.0),
            _dir: dir,
        };
        let deadline = Instant::now() + DEADLINE;
        while p.eval("document.body.dataset.ready || ''") != "1" {
            assert!(Instant::now() < deadline, "the page never drew");
        }
        let size = p.eval("JSON.stringify([document.getElementById('world').width, document.getElementById('world').height])");
        let size: Vec<f64> = serde_json::from_str(&size).unwrap();
        p.canvas = (size[0], size[1]);
        p
    }

    /// Sends one DevTools command and returns its result.
    fn call(&self, method: &str, params: Value) -> Value {
        let id = self.next.get();
        self.next.set(id + 1);
        let mut ws = self.ws.borrow_mut();
        ws.send(tungstenite::Message::Text(
            serde_json::json!({ "id": id, "method": method, "params": params })
                .to_string()
                .into(),
        ))
        .unwrap();
        loop {
            if let tungstenite::Message::Text(t) = ws.read().unwrap() {
                let v: Value = serde_json::from_str(&t).unwrap();
                if v["id"] == id {
                    assert!(v["error"].is_null(), "{method}: {v}");
                    return v["result"].clone();
                }
            }
        }
    }

    /// The value of a JavaScript expression, as a string.
    fn eval(&self, js: &str) -> String {
        let r = self.call(
            "Runtime.evaluate",
            serde_json::json!({ "expression": js, "returnByValue": true }),
        );
        match &r["result"]["value"] {
            Value::String(s) => s.clone(),
            v => v.to_string(),
        }
    }

    /// The page point of world point `p` (the canvas is at the page's corner).
    fn at(&self, p: (f64, f64)) -> (f64, f64) {
        let (x, y, scale) = self.view;
        (
            self.canvas.0 / 2.0 + (p.0 - x) * scale,
            self.canvas.1 / 2.0 - (p.1 - y) * scale,
        )
    }

    fn mouse(&self, kind: &str, (x, y): (f64, f64)) {
        self.call(
            "Input.dispatchMouseEvent",
            serde_json::json!({ "type": kind, "x": x, "y": y, "button": "left", "buttons": 1, "clickCount": 1 }),
        );
    }

    /// Presses at `from`, moves to `to` and lets go there.
    fn drag(&self, from: (f64, f64), to: (f64, f64)) {
        self.mouse("mousePressed", from);
        self.mouse("mouseMoved", to);
        self.mouse("mouseReleased", to);
    }

    /// Clicks the middle of the element `selector` names.
    fn click_element(&self, selector: &str) {
        let r = self.eval(&format!(
            "JSON.stringify((r => [r.x + r.width / 2, r.y + r.height / 2])(document.querySelector('{selector}').getBoundingClientRect()))"
        ));
        let r: Vec<f64> = serde_json::from_str(&r).unwrap();
        self.mouse("mousePressed", (r[0], r[1]));
        self.mouse("mouseReleased", (r[0], r[1]));
        assert_eq!(
            self.eval(&format!(
                "String(document.querySelector('{selector}').checked)"
            )),
            "true"
        );
    }
}

impl Drop for Page {
    fn drop(&mut self) {
        let _ = self.browser.kill();
        let _ = self.browser.wait();
    }
}

/// The README's picture of the view (docs/view.png): worlds/nav.cfg with a
/// goal given. Checked here for what it must show: amcl's estimate
/// (magenta) and the planner's path (orange) over the office. With
/// `TROUPE_BLESS=1` the picture is written to docs/view.png.
fn readme_picture(browser: &Path, base: &str) {
    let dir = std::env::temp_dir().join(troupe_tests::unique_namespace("viewshot"));
    std::fs::create_dir_all(&dir).unwrap();
    let img = screenshot(
        browser,
        &format!("{base}?still&device=6665:laser:0"),
        (1000, 650),
        &dir,
    );
    let count = |want: [u8; 3]| img.pixels().filter(|p| p.0 == want).count();
    assert!(count([0xe0, 0x70, 0x00]) > 20, "no planner path drawn");
    assert!(count([0xc0, 0x00, 0xc0]) > 20, "no amcl estimate drawn");
    if std::env::var_os("TROUPE_BLESS").is_some() {
        let to = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/view.png");
        img.save(&to).unwrap();
        eprintln!("wrote {}", to.display());
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// worlds/slam.cfg: the slam driver's map grows as r0 drives, and the view
/// draws it anew each time the map says it changed.
#[test]
fn the_view_redraws_the_map_slam_builds() {
    let cfg = Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds/slam.cfg");
    let stack = Viewed::launch("viewslam", &cfg, &["--speedup", "4"]);
    let base = stack.base.clone();
    let area = || {
        let world = json(&base, "/api/world");
        world["maps"]
            .as_array()
            .and_then(|m| m.iter().find(|m| m["device"] == "6665:map:0"))
            .map_or(0, |m| {
                m["width"].as_u64().unwrap_or(0) * m["height"].as_u64().unwrap_or(0)
            })
    };
    let first = frame_where(&base, |f| f["map_version"].as_u64().is_some_and(|v| v >= 1));
    let (v0, a0) = (first["map_version"].as_u64().unwrap_or(0), area());
    assert!(a0 > 0, "no map drawn at version {v0}");
    let later = frame_where(&base, |f| {
        f["map_version"].as_u64().is_some_and(|v| v > v0 + 2) && area() > a0
    });
    assert!(later["maps"].as_u64() >= Some(1), "{later}");
}
