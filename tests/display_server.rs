//! `--display-server`: the image streamed to a tev viewer, here a loopback listener that
//! decodes tev's packets (u32 length, u8 type, fields) the way tev does. The decoded final
//! image is the rendered image bit for bit; a missing or vanishing viewer costs a warning,
//! never the render; bad HOST:PORT values are refused by name.

mod common;

use common::root;
use std::io::Read;
use std::net::TcpListener;
use std::path::Path;
use std::process::{Command, Output};
use std::thread::JoinHandle;

fn pcbpt(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_pcbpt")).args(args).output().expect("runs the binary")
}

/// A render of the Cornell box at 70×40 (a second row and column of partial 64-pixel tiles).
fn render(out: &Path, extra: &[&str]) -> Output {
    let scene = root().join("scenes/cornell-box/scene.xml");
    let mut args = vec!["render", scene.to_str().unwrap(), "-o", out.to_str().unwrap()];
    args.extend(["-D", "resx=70", "-D", "resy=40", "--threads", "2"]);
    args.extend(extra);
    pcbpt(&args)
}

/// What the viewer saw.
#[derive(Debug, Default)]
struct Viewer {
    name: String,
    width: u32,
    height: u32,
    channels: Vec<String>,
    /// RGB, row by row.
    image: Vec<[f32; 3]>,
    updates: usize,
    /// Update packets before the image was created, or outside it, or for another image.
    stray: Vec<String>,
}

/// Reads tev packets' fields in order.
struct Fields<'a>(&'a [u8]);

impl Fields<'_> {
    fn take(&mut self, n: usize) -> &[u8] {
        let (a, b) = self.0.split_at(n);
        self.0 = b;
        a
    }
    fn u8(&mut self) -> u8 {
        self.take(1)[0]
    }
    fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.take(4).try_into().unwrap())
    }
    fn u64(&mut self) -> u64 {
        u64::from_le_bytes(self.take(8).try_into().unwrap())
    }
    fn string(&mut self) -> String {
        let end = self.0.iter().position(|&b| b == 0).expect("a zero-terminated string");
        let s = String::from_utf8(self.take(end).to_vec()).unwrap();
        self.take(1);
        s
    }
}

impl Viewer {
    fn packet(&mut self, body: &[u8]) {
        let mut f = Fields(body);
        match f.u8() {
            // CreateImage: grab focus, name, width, height, channel count, channel names.
            4 => {
                f.u8();
                self.name = f.string();
                self.width = f.u32();
                self.height = f.u32();
                let n = f.u32();
                self.channels = (0..n).map(|_| f.string()).collect();
                self.image = vec![[0.0; 3]; (self.width * self.height) as usize];
            }
            // UpdateImage (version 3): grab focus, name, channel count, names, x, y, width,
            // height, an offset and a stride per channel, then the floats.
            6 => {
                f.u8();
                let name = f.string();
                let n = f.u32() as usize;
                let names: Vec<String> = (0..n).map(|_| f.string()).collect();
                let (x, y, w, h) = (f.u32(), f.u32(), f.u32(), f.u32());
                let offsets: Vec<u64> = (0..n).map(|_| f.u64()).collect();
                let strides: Vec<u64> = (0..n).map(|_| f.u64()).collect();
                let data: Vec<f32> = f.0.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect();
                if name != self.name || self.image.is_empty() || x + w > self.width || y + h > self.height {
                    self.stray.push(format!("{name} {x},{y} {w}×{h}"));
                    return;
                }
                self.updates += 1;
                for (c, channel) in names.iter().enumerate() {
                    let k = ["R", "G", "B"].iter().position(|&r| r == channel).expect("an R, G or B channel");
                    for i in 0..(w * h) as usize {
                        let (px, py) = (x + i as u32 % w, y + i as u32 / w);
                        let v = data[(offsets[c] + i as u64 * strides[c]) as usize];
                        self.image[(py * self.width + px) as usize][k] = v;
                    }
                }
            }
            t => self.stray.push(format!("packet type {t}")),
        }
    }
}

/// A viewer on a loopback port that reads one connection to its end.
fn listen() -> (String, JoinHandle<Viewer>) {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let address = listener.local_addr().unwrap().to_string();
    let viewer = std::thread::spawn(move || {
        let (mut stream, _) = listener.accept().unwrap();
        let mut bytes = Vec::new();
        stream.read_to_end(&mut bytes).unwrap();
        let mut v = Viewer::default();
        let mut rest = &bytes[..];
        while !rest.is_empty() {
            // The length counts its own four bytes.
            let len = u32::from_le_bytes(rest[..4].try_into().unwrap()) as usize;
            v.packet(&rest[4..len]);
            rest = &rest[len..];
        }
        v
    });
    (address, viewer)
}

fn bits(p: [f32; 3]) -> [u32; 3] {
    p.map(f32::to_bits)
}

/// The stream of a render decodes to its output image, bit for bit, and streaming leaves
/// the image as a render without a viewer makes it.
fn streams_the_rendered_image(integrator: &str, spp: &str) {
    let d = tempfile::tempdir().unwrap();
    let (address, viewer) = listen();
    let out = d.path().join("shown.exr");
    let o = render(&out, &["--integrator", integrator, "--spp", spp, "--display-server", &address]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(!err.contains("warning: --display-server"), "{err}");
    let v = viewer.join().unwrap();
    assert_eq!((v.name.as_str(), v.width, v.height), ("shown.exr", 70, 40));
    assert_eq!(v.channels, ["R", "G", "B"]);
    assert!(v.stray.is_empty(), "{:?}", v.stray);
    // The final image is sent whole: two rows of two tiles at least.
    assert!(v.updates >= 4, "{} updates", v.updates);
    let img = pcbpt::image_io::read_exr(&out).unwrap();
    assert_eq!((img.width, img.height), (70, 40));
    assert!(img.mean() > 0.0);
    for (i, (shown, written)) in v.image.iter().zip(&img.pixels).enumerate() {
        assert_eq!(bits(*shown), bits(written.to_array()), "pixel {i} of {integrator}");
    }
    let plain = d.path().join("plain.exr");
    let o = render(&plain, &["--integrator", integrator, "--spp", spp]);
    assert!(o.status.success());
    common::distributed::assert_same_bits(&out, &plain);
}

#[test]
fn the_stream_decodes_to_the_rendered_image() {
    streams_the_rendered_image("bdpt", "4");
}

#[test]
fn markov_chain_renders_stream_their_image_too() {
    streams_the_rendered_image("pssmlt", "2");
}

#[test]
fn without_a_viewer_the_render_warns_and_goes_on() {
    let d = tempfile::tempdir().unwrap();
    // A port nothing listens on any more.
    let address = TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().to_string();
    let out = d.path().join("alone.exr");
    let o = render(&out, &["--integrator", "path", "--spp", "2", "--display-server", &address]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert_eq!(err.matches("warning: --display-server").count(), 1, "{err}");
    assert!(err.contains(&format!("cannot connect to {address}")), "{err}");
    assert!(pcbpt::image_io::read_exr(&out).unwrap().mean() > 0.0);
}

#[test]
fn a_viewer_that_goes_away_does_not_stop_the_render() {
    let d = tempfile::tempdir().unwrap();
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let address = listener.local_addr().unwrap().to_string();
    // Reads the start of the stream, then closes the connection.
    let viewer = std::thread::spawn(move || {
        let (mut stream, _) = listener.accept().unwrap();
        let mut start = [0u8; 4];
        stream.read_exact(&mut start).unwrap();
    });
    let out = d.path().join("left.exr");
    let o = render(&out, &["--integrator", "path", "--time", "1.5", "--display-server", &address]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.matches("warning: --display-server").count() <= 1, "{err}");
    assert!(!err.contains("panicked"), "{err}");
    viewer.join().unwrap();
    assert!(pcbpt::image_io::read_exr(&out).unwrap().mean() > 0.0);
}

#[test]
fn bad_addresses_are_refused_by_name() {
    let d = tempfile::tempdir().unwrap();
    for bad in ["localhost", ":14158", "localhost:0", "localhost:70000", "localhost:tev"] {
        let out = d.path().join("bad.exr");
        let o = render(&out, &["--spp", "1", "--display-server", bad]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{bad} accepted");
        assert!(err.contains("--display-server") && !err.contains("panicked"), "{bad}: {err}");
        assert!(!out.exists());
    }
}
