//! `courtyard`: a lighting test, lit the way production scenes are. A walled courtyard under a
//! roof rim around a wide opening, lit only by an `infinite` light with a sky map (`sky.pfm`:
//! bright at the zenith, dark below the horizon) and a sun (`distant`) whose light falls
//! through the opening onto the floor: the walls under the rim see the sun not at all and
//! the sky only through the opening, so much of what they show is sky and light bounced off
//! the sunlit floor (`--bounces`). Standard pbrt-v3, 18 triangles and a 64×32 PFM.

use std::path::Path;

use crate::{GenError, GenProgress, GenSummary};

/// Options of `motu gen courtyard`.
#[derive(Clone, Debug, PartialEq)]
pub struct CourtyardOptions {
    pub width: u32,
    pub height: u32,
    /// Sky map resolution (width; the height is half).
    pub sky_width: u32,
}

impl Default for CourtyardOptions {
    fn default() -> Self {
        Self {
            width: 64,
            height: 64,
            sky_width: 64,
        }
    }
}

/// Half the courtyard's side, its wall height and the opening's half side (world units).
const HALF: f64 = 5.0;
const WALL: f64 = 4.0;
const OPENING: f64 = 3.5;

/// Sky radiance towards light-space direction (θ from the zenith).
fn sky_radiance(theta: f64, phi: f64) -> [f32; 3] {
    let up = theta.cos();
    if up < 0.0 {
        return [0.04, 0.035, 0.03];
    }
    // Brighter towards the zenith; a little warmer on one side so the map is not symmetric.
    let warm = 0.15 * (1.0 + phi.cos()) * (1.0 - up);
    let k = 0.35 + 0.85 * up;
    [
        (k * (0.55 + warm)) as f32,
        (k * 0.7) as f32,
        (k * (1.0 - 0.5 * warm)) as f32,
    ]
}

/// The sky map as a PFM (little-endian, rows bottom-up as PFM stores them).
fn sky_pfm(w: u32, h: u32) -> Vec<u8> {
    let mut out = format!("PF\n{w} {h}\n-1.0\n").into_bytes();
    for row in (0..h).rev() {
        let theta = std::f64::consts::PI * (f64::from(row) + 0.5) / f64::from(h);
        for col in 0..w {
            let phi = std::f64::consts::TAU * (f64::from(col) + 0.5) / f64::from(w);
            for c in sky_radiance(theta, phi) {
                out.extend(c.to_le_bytes());
            }
        }
    }
    out
}

/// A quad as a two-triangle `trianglemesh` with `material`.
fn quad(out: &mut String, material: &str, p: [[f64; 3]; 4]) {
    let pts: Vec<String> = p
        .iter()
        .map(|v| format!("{} {} {}", v[0], v[1], v[2]))
        .collect();
    out.push_str(&format!(
        "AttributeBegin\n  NamedMaterial \"{material}\"\n  Shape \"trianglemesh\" \"integer indices\" [0 1 2 0 2 3]\n    \"point P\" [{}]\nAttributeEnd\n",
        pts.join("  ")
    ));
}

fn scene_text(o: &CourtyardOptions) -> String {
    let (h, w, a) = (HALF, WALL, OPENING);
    let mut s = String::new();
    s.push_str("# motu gen courtyard: sky map + sun through a roof opening\n");
    s.push_str("LookAt 3.8 1.6 3.8  -2 1.5 -3  0 1 0\n");
    s.push_str("Camera \"perspective\" \"float fov\" [70]\n");
    s.push_str(&format!(
        "Film \"image\" \"integer xresolution\" [{}] \"integer yresolution\" [{}]\n",
        o.width, o.height
    ));
    s.push_str("WorldBegin\n");
    // pbrt-v3's lat-long map has +z at its top row: rotate it to +y (`Rotate -90 1 0 0`,
    // written as its matrix, column-major as pbrt reads it).
    s.push_str("AttributeBegin\n  Transform [1 0 0 0  0 0 -1 0  0 1 0 0  0 0 0 1]\n  LightSource \"infinite\" \"string mapname\" \"sky.pfm\" \"rgb L\" [1 1 1]\nAttributeEnd\n");
    s.push_str("LightSource \"distant\" \"point from\" [-1 6 0.5] \"point to\" [0 0 0] \"rgb L\" [5 4.7 4.2]\n");
    s.push_str(
        "MakeNamedMaterial \"floor\" \"string type\" \"matte\" \"rgb Kd\" [0.55 0.5 0.45]\n",
    );
    s.push_str("MakeNamedMaterial \"wall\" \"string type\" \"matte\" \"rgb Kd\" [0.75 0.62 0.5]\n");
    s.push_str("MakeNamedMaterial \"roof\" \"string type\" \"matte\" \"rgb Kd\" [0.4 0.4 0.42]\n");
    quad(
        &mut s,
        "floor",
        [[-h, 0.0, -h], [-h, 0.0, h], [h, 0.0, h], [h, 0.0, -h]],
    );
    for (x0, z0, x1, z1) in [
        (-h, -h, h, -h),
        (h, -h, h, h),
        (h, h, -h, h),
        (-h, h, -h, -h),
    ] {
        quad(
            &mut s,
            "wall",
            [[x0, 0.0, z0], [x1, 0.0, z1], [x1, w, z1], [x0, w, z0]],
        );
    }
    // The roof: four slabs around the opening.
    for (x0, z0, x1, z1) in [
        (-h, -h, h, -a),
        (-h, a, h, h),
        (-h, -a, -a, a),
        (a, -a, h, a),
    ] {
        quad(
            &mut s,
            "roof",
            [[x0, w, z0], [x1, w, z0], [x1, w, z1], [x0, w, z1]],
        );
    }
    s.push_str("WorldEnd\n");
    s
}

pub(crate) fn generate(
    o: &CourtyardOptions,
    root: &Path,
    progress: &mut dyn FnMut(GenProgress),
) -> Result<GenSummary, GenError> {
    if o.width == 0 || o.height == 0 {
        return Err(GenError::InvalidOption {
            option: "width/height",
            reason: "the image needs at least one pixel".into(),
        });
    }
    if !(4..=8192).contains(&o.sky_width) {
        return Err(GenError::InvalidOption {
            option: "sky_width",
            reason: "must be in 4..=8192".into(),
        });
    }
    let scene = scene_text(o);
    let sky = sky_pfm(o.sky_width, o.sky_width / 2);
    let mut bytes = 0u64;
    for (name, data) in [("sky.pfm", sky), ("scene.pbrt", scene.into_bytes())] {
        let path = root.join(name);
        std::fs::write(&path, &data).map_err(|source| GenError::Io { path, source })?;
        bytes += data.len() as u64;
    }
    progress(GenProgress {
        files_written: 2,
        files_total: 2,
        bytes_written: bytes,
    });
    Ok(GenSummary {
        scene_path: root.join("scene.pbrt"),
        files_written: 2,
        bytes_written: bytes,
        object_instances: 0,
        flattened_instances: 0,
        unique_triangles: 2 * (1 + 4 + 4),
        instanced_triangles: 2 * (1 + 4 + 4),
        elements: vec!["main".into()],
        cameras: vec!["default".into()],
        nested_instancing: false,
        syntax: None,
    })
}

#[cfg(test)]
mod tests;
