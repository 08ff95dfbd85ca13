//! Partial renders and their merge: one render cut into chunks of iterations, each rendered
//! anywhere (`pcbpt render --chunk I/N`), merged into the image one process gives
//! (`pcbpt merge`).
//!
//! A part is an EXR file. Its `R`, `G`, `B` channels are the part's own image (a preview any
//! viewer opens); its other channels hold the film's exact sums bit for bit
//! ([`crate::film::ExactSum`], two `f64` per sum, each as two `u32` channels): the camera
//! samples' `Σ w r, Σ w g, Σ w b, Σ w` and the splats' `r, g, b`. A JSON attribute
//! (`pcbpt.part`) says which render the part belongs to — a hash of the scene's files and
//! parameter overrides, and every setting that changes the image — which iterations it
//! holds, its light paths and dropped samples, and for the Markov chains their
//! normalisation.
//!
//! For every integrator that renders iterations (path, lighttrace, bdpt, eorr, lvc, pcbpt)
//! the merged film is the one-process film exactly: sums are exact and each part's
//! iterations are those of the full render (see [`crate::integrator::render_iterations`]).
//! PSSMLT's parts are independent sets of chains, each with its own bootstrap: their
//! histograms are added with the normalisation their chains splatted with divided out, and
//! the image is scaled by the normalisations of all parts, weighted by the samples behind
//! each. The merged image converges to the same answer, but is not the one-process image.

use crate::error::{Error, Result};
use crate::film::{ExactSum, Film, Filter};
use crate::integrator::pssmlt::PssmltStats;
use crate::integrator::{Budget, RenderOptions, RenderOutput};
use crate::math::Rgb;
use crate::scene::Scene;
use exr::prelude::{
    AnyChannel, AnyChannels, AttributeValue, Encoding, FlatSamples, Image, Layer, LayerAttributes, ReadChannels,
    ReadLayers, Text, WritableImage,
};
use serde::{Deserialize, Serialize};
use std::io::Read;
use std::ops::Range;
use std::path::{Path, PathBuf};

/// Version of the part format.
const FORMAT: u32 = 1;
/// The EXR attribute that holds a part's [`PartInfo`].
const ATTRIBUTE: &str = "pcbpt.part";
/// Names of the seven sums per pixel ([`Film::sums`]).
const SUMS: [&str; 7] = ["camera.R", "camera.G", "camera.B", "camera.W", "splat.R", "splat.G", "splat.B"];

/// The Markov chains' normalisation in a part.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct ChainsInfo {
    /// `b` the chains splatted with (their bootstrap's).
    pub splatted_b: f64,
    /// `b` from the bootstrap and every large step.
    pub normalisation: f64,
    /// Independent samples behind `normalisation`.
    pub normalisation_samples: u64,
    pub mutations: u64,
}

/// What a part's metadata says.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct PartInfo {
    pub format: u32,
    /// Identifies the render: equal for every part of one render.
    pub render: serde_json::Value,
    /// Iterations (samples or mutations per pixel) of the whole render.
    pub total: u32,
    /// The iterations this part holds.
    pub iterations: Range<u32>,
    pub width: u32,
    pub height: u32,
    pub filter: Filter,
    pub light_paths: u64,
    pub invalid_samples: u64,
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub chains: Option<ChainsInfo>,
    /// Seconds the part's render took (informative).
    pub seconds: f64,
}

/// A part read back.
pub struct Part {
    pub path: PathBuf,
    pub info: PartInfo,
    pub film: Film,
}

/// xxh3-128 of the files a scene was read from (contents, in the order read) and of the
/// parameter overrides, as hex.
pub fn scene_hash(scene: &Scene, overrides: &[(String, String)]) -> Result<String> {
    let mut h = xxhash_rust::xxh3::Xxh3::new();
    let mut buf = vec![0u8; 1 << 20];
    for path in &scene.stats.files {
        let mut f = std::fs::File::open(path).map_err(|e| Error::in_file(path, format!("cannot read: {e}")))?;
        h.update(b"\0file\0");
        loop {
            let n = f.read(&mut buf).map_err(|e| Error::in_file(path, format!("cannot read: {e}")))?;
            if n == 0 {
                break;
            }
            h.update(&buf[..n]);
        }
    }
    let mut defines: Vec<_> = overrides.iter().collect();
    defines.sort();
    for (k, v) in defines {
        h.update(format!("\0define\0{k}={v}").as_bytes());
    }
    Ok(format!("{:032x}", h.digest128()))
}

/// What identifies a render: the scene's hash and every setting that changes its image
/// (not the thread count, tile size or time spent).
pub fn render_identity(scene: &Scene, opts: &RenderOptions, scene_hash: &str) -> serde_json::Value {
    let spp = match opts.run.budget {
        Budget::Spp(s) => Some(s),
        Budget::Time(_) => None,
    };
    let mut identity = serde_json::json!({
        "scene": scene_hash,
        "integrator": opts.integrator(),
        "options": opts.method,
        "spp": spp,
        "seed": opts.run.seed,
        "max_depth": scene.integrator.max_depth,
        "rr_depth": scene.integrator.rr_depth,
        "hide_emitters": scene.integrator.hide_emitters,
        "film": [scene.film.width, scene.film.height],
        "backend": scene.accel.backend().to_string(),
    });
    // What only some renders set, named only where set (parts of renders without them keep
    // their identity).
    if scene.sampler.kind != crate::sampling::SamplerKind::Independent {
        identity["sampler"] = serde_json::json!(scene.sampler.kind);
    }
    if scene.integrator.strict_normals {
        identity["strict_normals"] = serde_json::json!(true);
    }
    identity
}

/// The iterations of chunk `index` of `count` of a render of `total` iterations:
/// `⌊index·total/count⌋ .. ⌊(index+1)·total/count⌋`.
pub fn chunk(index: u32, count: u32, total: u32) -> Result<Range<u32>> {
    if count == 0 || index >= count {
        return Err(Error::Usage(format!("--chunk {index}/{count}: the index must be below the count (0-based)")));
    }
    let at = |i: u32| (i as u64 * total as u64 / count as u64) as u32;
    let r = at(index)..at(index + 1);
    if r.is_empty() {
        return Err(Error::Usage(format!(
            "--chunk {index}/{count} of a render of {total} samples per pixel is empty: use at most {total} chunks"
        )));
    }
    Ok(r)
}

/// The part of a finished chunk render.
pub fn part_info(out: &RenderOutput, render: serde_json::Value, total: u32, filter: Filter) -> Result<PartInfo> {
    let film = out.film.as_ref().ok_or_else(|| Error::Usage("this render keeps no film".into()))?;
    let s = &out.stats;
    if s.interrupted {
        return Err(Error::Usage("the chunk was interrupted: no part is written for an incomplete chunk".into()));
    }
    let iterations = s.iterations.clone().unwrap_or(0..total);
    let chains = s.details.get::<PssmltStats>().map(|&PssmltStats { mlt: m }| ChainsInfo {
        splatted_b: m.bootstrap_normalisation,
        normalisation: m.normalisation,
        normalisation_samples: m.bootstrap_samples + m.large_proposed,
        mutations: m.mutations,
    });
    Ok(PartInfo {
        format: FORMAT,
        render,
        total,
        iterations,
        width: out.width,
        height: out.height,
        filter,
        light_paths: film.light_paths,
        invalid_samples: film.invalid_samples,
        chains,
        seconds: s.seconds,
    })
}

/// Escapes every non-ASCII character of JSON text (EXR attribute text is 8-bit).
fn ascii_json(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        if c.is_ascii() {
            out.push(c);
        } else {
            let mut units = [0u16; 2];
            for u in c.encode_utf16(&mut units) {
                out.push_str(&format!("\\u{u:04x}"));
            }
        }
    }
    out
}

/// Writes a part atomically: the preview `image` and the film's sums, with `info`.
pub fn write_part(path: &Path, image: &[Rgb], film: &Film, info: &PartInfo) -> Result<()> {
    if crate::image_io::Format::from_path(path)? != crate::image_io::Format::Exr {
        return Err(Error::Usage(format!("{}: a partial render is written as an EXR file", path.display())));
    }
    let (w, h) = (info.width as usize, info.height as usize);
    let sums = film.sums();
    let mut list = exr::prelude::SmallVec::new();
    for (c, name) in ["R", "G", "B"].into_iter().enumerate() {
        list.push(AnyChannel::new(name, FlatSamples::F32(image.iter().map(|p| p[c]).collect())));
    }
    for (k, name) in SUMS.iter().enumerate() {
        for part in ["hi", "lo"] {
            let bits: Vec<u64> = sums.iter().map(|s| if part == "hi" { s[k].hi } else { s[k].lo }.to_bits()).collect();
            list.push(AnyChannel::new(
                format!("{name}.{part}.upper").as_str(),
                FlatSamples::U32(bits.iter().map(|b| (b >> 32) as u32).collect()),
            ));
            list.push(AnyChannel::new(
                format!("{name}.{part}.lower").as_str(),
                FlatSamples::U32(bits.iter().map(|b| *b as u32).collect()),
            ));
        }
    }
    let json = ascii_json(&serde_json::to_string(info).map_err(|e| Error::Usage(e.to_string()))?);
    let mut attributes = LayerAttributes::named("pcbpt partial render");
    attributes.other.insert(Text::from(ATTRIBUTE), AttributeValue::Text(Text::from(json.as_str())));
    let layer = Layer::new((w, h), attributes, Encoding::SMALL_LOSSLESS, AnyChannels::sort(list));
    crate::image_io::write_atomically(path, |tmp| {
        Image::from_layer(layer).write().non_parallel().to_file(tmp).map_err(|e| format!("cannot write EXR: {e}"))
    })
}

/// Reads a part, checking that it is one.
pub fn read_part(path: &Path) -> Result<Part> {
    let bad = |msg: String| Error::in_file(path, msg);
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .map_err(|e| bad(format!("cannot read EXR: {e}")))?;
    let layer = &image.layer_data;
    let info: PartInfo = match layer.attributes.other.get(&Text::from(ATTRIBUTE)) {
        Some(AttributeValue::Text(t)) => {
            serde_json::from_str(&t.to_string()).map_err(|e| bad(format!("the part's metadata cannot be read: {e}")))?
        }
        _ => return Err(bad("not a partial render (no pcbpt.part metadata): render it with --chunk".into())),
    };
    if info.format != FORMAT {
        return Err(bad(format!("part format {} (this pcbpt reads format {FORMAT})", info.format)));
    }
    let (w, h) = (info.width as usize, info.height as usize);
    if (layer.size.width(), layer.size.height()) != (w, h) {
        return Err(bad(format!("{}×{} pixels, its metadata says {w}×{h}", layer.size.width(), layer.size.height())));
    }
    let channel = |name: &str| -> Result<&Vec<u32>> {
        match layer.channel_data.list.iter().find(|c| c.name == *name).map(|c| &c.sample_data) {
            Some(FlatSamples::U32(v)) if v.len() == w * h => Ok(v),
            _ => Err(bad(format!("channel {name} is missing or not 32-bit integers"))),
        }
    };
    let mut sums = vec![[ExactSum::default(); 7]; w * h];
    for (k, name) in SUMS.iter().enumerate() {
        for part in ["hi", "lo"] {
            let (upper, lower) = (channel(&format!("{name}.{part}.upper"))?, channel(&format!("{name}.{part}.lower"))?);
            for (i, s) in sums.iter_mut().enumerate() {
                let v = f64::from_bits(((upper[i] as u64) << 32) | lower[i] as u64);
                if part == "hi" {
                    s[k].hi = v;
                } else {
                    s[k].lo = v;
                }
            }
        }
    }
    let film = Film::from_sums(info.width, info.height, info.filter, &sums, info.light_paths, info.invalid_samples);
    Ok(Part { path: path.to_path_buf(), info, film })
}

/// A merge of parts.
pub struct Merged {
    pub width: u32,
    pub height: u32,
    pub image: Vec<Rgb>,
    /// Iterations of the whole render.
    pub total: u32,
    /// Iteration ranges no part holds (empty unless merging what has arrived).
    pub missing: Vec<Range<u32>>,
    pub light_paths: u64,
    pub invalid_samples: u64,
    /// Seconds the parts' renders took, summed.
    pub render_seconds: f64,
}

/// The top-level keys of two render identities that differ.
fn differences(a: &serde_json::Value, b: &serde_json::Value) -> Vec<String> {
    let (Some(a), Some(b)) = (a.as_object(), b.as_object()) else { return vec!["the render".into()] };
    let mut keys: Vec<&String> = a.keys().chain(b.keys()).collect();
    keys.sort();
    keys.dedup();
    keys.into_iter().filter(|k| a.get(*k) != b.get(*k)).map(|k| k.to_string()).collect()
}

/// Merges parts of one render. They must share the render's identity and size, and hold
/// disjoint iterations; unless `allow_missing`, together every iteration of the render.
pub fn merge(mut parts: Vec<Part>, allow_missing: bool) -> Result<Merged> {
    let Some(first) = parts.first() else { return Err(Error::Usage("no parts to merge".into())) };
    let (name0, info0) = (first.path.display().to_string(), first.info.clone());
    for p in &parts[1..] {
        let i = &p.info;
        if i.render != info0.render || i.total != info0.total || (i.width, i.height) != (info0.width, info0.height) {
            let mut what = differences(&i.render, &info0.render);
            if i.total != info0.total {
                what.push("total iterations".into());
            }
            return Err(Error::in_file(
                &p.path,
                format!("belongs to another render than {name0} (they differ in: {})", what.join(", ")),
            ));
        }
    }
    parts.sort_by_key(|p| (p.info.iterations.start, p.info.iterations.end));
    for pair in parts.windows(2) {
        let (a, b) = (&pair[0], &pair[1]);
        if b.info.iterations.start < a.info.iterations.end {
            return Err(Error::in_file(
                &b.path,
                format!(
                    "iterations {:?} overlap those of {} ({:?}): each iteration must be merged once",
                    b.info.iterations,
                    a.path.display(),
                    a.info.iterations
                ),
            ));
        }
    }
    let mut missing = Vec::new();
    let mut at = 0;
    for p in &parts {
        if p.info.iterations.start > at {
            missing.push(at..p.info.iterations.start);
        }
        at = p.info.iterations.end;
    }
    if at < info0.total {
        missing.push(at..info0.total);
    }
    if !missing.is_empty() && !allow_missing {
        let list: Vec<String> = missing.iter().map(|r| format!("{}..{}", r.start, r.end)).collect();
        return Err(Error::Usage(format!(
            "the parts do not cover the render's iterations 0..{}: missing {} (merge what has arrived with --partial)",
            info0.total,
            list.join(", ")
        )));
    }
    let (w, h) = (info0.width, info0.height);
    let mut film = Film::new(w, h, info0.filter);
    let render_seconds = parts.iter().map(|p| p.info.seconds).sum();
    let image = if info0.chains.is_some() {
        // Markov chains: histograms without their own normalisation, scaled by the
        // normalisation of all parts.
        let (mut b_sum, mut n_sum) = (0.0f64, 0u64);
        for p in &parts {
            let c = p.info.chains.as_ref().ok_or_else(|| Error::in_file(&p.path, "a part without its chains' data"))?;
            if c.splatted_b > 0.0 {
                film.add_scaled_splats(&p.film, 1.0 / c.splatted_b);
            }
            film.light_paths += p.film.light_paths;
            film.invalid_samples += p.film.invalid_samples;
            b_sum += c.normalisation * c.normalisation_samples as f64;
            n_sum += c.normalisation_samples;
        }
        let b = if n_sum > 0 { b_sum / n_sum as f64 } else { 0.0 };
        film.develop().into_iter().map(|p| p * b as f32).collect()
    } else {
        for p in &parts {
            film.merge_film(&p.film);
        }
        film.develop()
    };
    Ok(Merged {
        width: w,
        height: h,
        image,
        total: info0.total,
        missing,
        light_paths: film.light_paths,
        invalid_samples: film.invalid_samples,
        render_seconds,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chunks_cover_the_render_once() {
        for total in [1u32, 7, 16, 1000] {
            for count in 1..=total.min(9) {
                let mut at = 0;
                for i in 0..count {
                    let r = chunk(i, count, total).unwrap();
                    assert_eq!(r.start, at);
                    at = r.end;
                }
                assert_eq!(at, total);
            }
        }
        assert!(chunk(4, 4, 10).is_err());
        assert!(chunk(0, 3, 2).is_err(), "an empty chunk is refused");
    }

    #[test]
    fn json_is_kept_ascii() {
        let s = ascii_json(r#"{"a":"3×4 ü 🎉"}"#);
        assert!(s.is_ascii());
        let v: serde_json::Value = serde_json::from_str(&s).unwrap();
        assert_eq!(v["a"], "3×4 ü 🎉");
    }
}
