//! The live preview of `--display-server HOST:PORT` (pbrt-v4's flag): the image streamed to
//! the tev viewer over its TCP protocol while it renders.
//!
//! The packets are the `tev_client` crate's (tev's IPC protocol: each packet a little-endian
//! `u32` length that counts itself, a `u8` type, then its fields; strings end with a zero
//! byte). The image is created once (CreateImage, channels R, G, B), then each image the
//! render loops offer ([`Preview`]) is sent as UpdateImage packets of [`TILE`]-pixel tiles,
//! only those whose pixels changed since the last image sent; at the end the final image is
//! sent whole.
//!
//! Rendering never waits on the viewer: a thread of its own writes to the socket and takes
//! one image at a time; the loops develop an image only when that thread is idle and at most
//! every [`INTERVAL`]. A viewer that is absent (nothing listens) or goes away (a write fails
//! or times out) costs one warning, and the render goes on without a preview.

use crate::integrator::Preview;
use crate::math::Rgb;
use std::net::{SocketAddr, TcpStream, ToSocketAddrs};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tev_client::{PacketCreateImage, PacketUpdateImage, TevClient};

/// Side of the square tiles the image is sent in (pixels).
pub const TILE: u32 = 64;

/// Least time between two images sent while rendering.
pub const INTERVAL: Duration = Duration::from_millis(500);

/// How long connecting to the viewer may take before the render goes on without it.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(2);

/// How long one write to the viewer may stall before the viewer counts as gone.
const WRITE_TIMEOUT: Duration = Duration::from_secs(5);

/// How long the end of the render waits for the final image to be sent.
const FINISH_TIMEOUT: Duration = Duration::from_secs(30);

const CHANNELS: [&str; 3] = ["R", "G", "B"];

/// Checks a `--display-server` value: `HOST:PORT`, a port from 1 to 65535.
pub fn parse_address(s: &str) -> Result<String, String> {
    let (host, port) = s.rsplit_once(':').ok_or_else(|| format!("expected HOST:PORT, got {s:?}"))?;
    if host.is_empty() {
        return Err(format!("no host in {s:?} (expected HOST:PORT, e.g. localhost:14158)"));
    }
    match port.parse::<u16>() {
        Ok(p) if p > 0 => Ok(s.to_string()),
        _ => Err(format!("the port of {s:?} is not a number from 1 to 65535")),
    }
}

/// An image for the sending thread.
struct Frame {
    pixels: Vec<Rgb>,
    /// Send every tile, changed or not (the final image).
    whole: bool,
}

/// What the render loops and the sending thread share.
#[derive(Debug)]
struct Shared {
    /// The viewer went away: nothing more is sent.
    gone: AtomicBool,
    /// The thread is sending an image.
    busy: AtomicBool,
    /// When the last image was offered.
    last: Mutex<Option<Instant>>,
    quiet: bool,
}

impl Shared {
    fn warn(&self, msg: &str) {
        if !self.quiet {
            eprintln!("warning: --display-server: {msg}; rendering goes on without the preview");
        }
    }
}

/// A connection to tev showing one image of the render.
#[derive(Debug)]
pub struct DisplayServer {
    width: u32,
    height: u32,
    shared: Arc<Shared>,
    frames: Mutex<Option<SyncSender<Frame>>>,
    /// Closed when the sending thread ends.
    ended: Mutex<Receiver<()>>,
}

impl DisplayServer {
    /// Connects to tev at `address` (`HOST:PORT`) and has it create the image `name` of
    /// `width × height` pixels. Without a viewer there, warns (unless `quiet`) and gives `None`.
    pub fn connect(address: &str, name: &str, width: u32, height: u32, quiet: bool) -> Option<DisplayServer> {
        let shared = Arc::new(Shared {
            gone: AtomicBool::new(false),
            busy: AtomicBool::new(false),
            last: Mutex::new(None),
            quiet,
        });
        let stream = match open(address) {
            Ok(s) => s,
            Err(e) => {
                shared.warn(&format!("cannot connect to {address}: {e}"));
                return None;
            }
        };
        let (tx, rx) = sync_channel::<Frame>(1);
        let (end_tx, end_rx) = sync_channel::<()>(0);
        let name = name.replace('\0', "");
        let thread_shared = shared.clone();
        let spawned = std::thread::Builder::new().name("tev".into()).spawn(move || {
            let _end = end_tx;
            send_all(TevClient::wrap(stream), &name, (width, height), rx, &thread_shared);
        });
        if let Err(e) = spawned {
            shared.warn(&format!("cannot start the sending thread: {e}"));
            return None;
        }
        Some(DisplayServer { width, height, shared, frames: Mutex::new(Some(tx)), ended: Mutex::new(end_rx) })
    }

    /// Sends the final image whole and waits (a bounded time) until it is sent.
    pub fn finish(&self, image: &[Rgb]) {
        let Some(tx) = self.frames.lock().ok().and_then(|mut f| f.take()) else { return };
        if image.len() == self.width as usize * self.height as usize && !self.shared.gone.load(Ordering::SeqCst) {
            // Waits for the image in flight: its writes time out if the viewer stalls.
            let _ = tx.send(Frame { pixels: image.to_vec(), whole: true });
        }
        drop(tx);
        if let Ok(ended) = self.ended.lock() {
            let _ = ended.recv_timeout(FINISH_TIMEOUT);
        }
    }
}

impl Preview for DisplayServer {
    fn wants(&self) -> bool {
        if self.shared.gone.load(Ordering::SeqCst) || self.shared.busy.load(Ordering::SeqCst) {
            return false;
        }
        let Ok(mut last) = self.shared.last.lock() else { return false };
        if last.is_some_and(|t| t.elapsed() < INTERVAL) {
            return false;
        }
        *last = Some(Instant::now());
        true
    }

    fn show(&self, width: u32, height: u32, _spp: u32, image: Vec<Rgb>) {
        if (width, height) != (self.width, self.height) || image.len() != width as usize * height as usize {
            return;
        }
        let Ok(frames) = self.frames.lock() else { return };
        if let Some(tx) = frames.as_ref() {
            self.shared.busy.store(true, Ordering::SeqCst);
            // The thread is behind: the image is dropped, not queued.
            if tx.try_send(Frame { pixels: image, whole: false }).is_err() {
                self.shared.busy.store(false, Ordering::SeqCst);
            }
        }
    }
}

/// A socket to `address`, tried address by address with a time limit, writes time-limited.
fn open(address: &str) -> std::io::Result<TcpStream> {
    let addrs: Vec<SocketAddr> = address.to_socket_addrs()?.collect();
    let mut last = std::io::Error::new(std::io::ErrorKind::NotFound, "the host has no address");
    for a in addrs {
        match TcpStream::connect_timeout(&a, CONNECT_TIMEOUT) {
            Ok(s) => {
                s.set_write_timeout(Some(WRITE_TIMEOUT))?;
                s.set_nodelay(true)?;
                return Ok(s);
            }
            Err(e) => last = e,
        }
    }
    Err(last)
}

/// The sending thread: creates the image, then sends the changed tiles of each frame until
/// the render drops its sender or a write fails.
fn send_all(mut client: TevClient, name: &str, (width, height): (u32, u32), frames: Receiver<Frame>, shared: &Shared) {
    let create = PacketCreateImage { image_name: name, grab_focus: true, width, height, channel_names: &CHANNELS };
    if let Err(e) = client.send(create) {
        return give_up(shared, &e);
    }
    // tev's new image is black: tiles still black need not be sent.
    let mut shown = vec![Rgb::ZERO; width as usize * height as usize];
    for frame in frames {
        let sent = send_frame(&mut client, name, width, &frame, &mut shown);
        shared.busy.store(false, Ordering::SeqCst);
        if let Err(e) = sent {
            return give_up(shared, &e);
        }
    }
}

fn give_up(shared: &Shared, e: &std::io::Error) {
    shared.gone.store(true, Ordering::SeqCst);
    shared.busy.store(false, Ordering::SeqCst);
    shared.warn(&format!("the viewer went away ({e})"));
}

/// A tile's pixel rectangle: x, y, width, height.
type Rect = (u32, u32, u32, u32);

/// The tiles of a `width × height` image, row by row.
fn tiles(width: u32, height: u32) -> impl Iterator<Item = Rect> {
    (0..height.div_ceil(TILE)).flat_map(move |ty| {
        (0..width.div_ceil(TILE)).map(move |tx| {
            let (x, y) = (tx * TILE, ty * TILE);
            (x, y, TILE.min(width - x), TILE.min(height - y))
        })
    })
}

/// Sends the tiles of `frame` that differ (bit for bit) from `shown`, all of them for a whole
/// frame, and records them as shown.
fn send_frame(client: &mut TevClient, name: &str, width: u32, frame: &Frame, shown: &mut [Rgb]) -> std::io::Result<()> {
    let row = |y: u32, x: u32, w: u32| {
        let start = (y * width + x) as usize;
        start..start + w as usize
    };
    let same = |a: &Rgb, b: &Rgb| a.to_array().map(f32::to_bits) == b.to_array().map(f32::to_bits);
    for (x, y, w, h) in tiles(width, frame.pixels.len() as u32 / width.max(1)) {
        let changed = (y..y + h).any(|yy| {
            let r = row(yy, x, w);
            !frame.pixels[r.clone()].iter().zip(&shown[r]).all(|(a, b)| same(a, b))
        });
        if !(frame.whole || changed) {
            continue;
        }
        let mut data = Vec::with_capacity(w as usize * h as usize * 3);
        for yy in y..y + h {
            let r = row(yy, x, w);
            data.extend(frame.pixels[r.clone()].iter().flat_map(|p| p.to_array()));
            shown[r.clone()].copy_from_slice(&frame.pixels[r]);
        }
        client.send(PacketUpdateImage {
            image_name: name,
            grab_focus: false,
            channel_names: &CHANNELS,
            channel_offsets: &[0, 1, 2],
            channel_strides: &[3, 3, 3],
            x,
            y,
            width: w,
            height: h,
            data: &data,
        })?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn addresses_need_a_host_and_a_port() {
        assert_eq!(parse_address("localhost:14158").as_deref(), Ok("localhost:14158"));
        assert_eq!(parse_address("[::1]:14158").as_deref(), Ok("[::1]:14158"));
        for bad in ["localhost", ":14158", "localhost:0", "localhost:65536", "localhost:port", "host:"] {
            assert!(parse_address(bad).is_err(), "{bad} accepted");
        }
    }

    #[test]
    fn tiles_cover_the_image_once() {
        let (w, h) = (150, 70);
        let mut count = vec![0u8; (w * h) as usize];
        for (x, y, tw, th) in tiles(w, h) {
            assert!(tw > 0 && th > 0 && tw <= TILE && th <= TILE);
            for yy in y..y + th {
                for xx in x..x + tw {
                    count[(yy * w + xx) as usize] += 1;
                }
            }
        }
        assert!(count.iter().all(|&c| c == 1));
        assert_eq!(tiles(w, h).count(), 3 * 2);
    }
}
