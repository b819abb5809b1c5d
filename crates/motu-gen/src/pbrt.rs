//! pbrt statement writers shared by the generators.

use crate::math::{Affine, Vec3};
use crate::text::{push_fixed, push_u64};

/// Which pbrt dialect a file is written in. Only parameter spellings differ
/// between the two for what the generators write.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Syntax {
    /// pbrt-v3: `"point P"`, `Film "image"`, `"matte"` with `"rgb Kd"`.
    V3,
    /// pbrt-v4: `"point3 P"`, `Film "rgb"`, `"diffuse"` with `"rgb reflectance"`.
    V4,
}

impl Syntax {
    pub(crate) fn point_type(self) -> &'static str {
        match self {
            Syntax::V3 => "point",
            Syntax::V4 => "point3",
        }
    }
}

/// A named perspective camera.
#[derive(Clone, Debug)]
pub(crate) struct CameraSpec {
    pub(crate) eye: Vec3,
    pub(crate) target: Vec3,
    pub(crate) fov_deg: f64,
}

pub(crate) fn push_vec(line: &mut Vec<u8>, v: Vec3, decimals: u32) {
    for (i, c) in v.iter().enumerate() {
        if i > 0 {
            line.push(b' ');
        }
        push_fixed(line, *c, decimals);
    }
}

/// `LookAt` + `Camera "perspective"`; the up vector is +y.
pub(crate) fn push_camera(line: &mut Vec<u8>, camera: &CameraSpec) {
    line.extend_from_slice(b"LookAt ");
    push_vec(line, camera.eye, 4);
    line.extend_from_slice(b"\n       ");
    push_vec(line, camera.target, 4);
    line.extend_from_slice(b"\n       0 1 0\nCamera \"perspective\" \"float fov\" [ ");
    push_fixed(line, camera.fov_deg, 4);
    line.extend_from_slice(b" ]\n");
}

pub(crate) fn push_film(
    line: &mut Vec<u8>,
    syntax: Syntax,
    width: u32,
    height: u32,
    filename: &str,
) {
    let film = match syntax {
        Syntax::V3 => "image",
        Syntax::V4 => "rgb",
    };
    line.extend_from_slice(format!("Film \"{film}\"\n    \"integer xresolution\" [ ").as_bytes());
    push_u64(line, u64::from(width));
    line.extend_from_slice(b" ]\n    \"integer yresolution\" [ ");
    push_u64(line, u64::from(height));
    line.extend_from_slice(format!(" ]\n    \"string filename\" [ \"{filename}\" ]\n").as_bytes());
    line.extend_from_slice(b"Sampler \"halton\" \"integer pixelsamples\" [ 16 ]\n");
}

/// A distant "sun" shining from `from` towards the origin.
pub(crate) fn push_sun(line: &mut Vec<u8>, syntax: Syntax, from: Vec3, radiance: Vec3) {
    let p = syntax.point_type();
    line.extend_from_slice(format!("LightSource \"distant\"\n    \"{p} from\" [ ").as_bytes());
    push_vec(line, from, 4);
    line.extend_from_slice(format!(" ]\n    \"{p} to\" [ 0 0 0 ]\n    \"rgb L\" [ ").as_bytes());
    push_vec(line, radiance, 4);
    line.extend_from_slice(b" ]\n");
}

/// A diffuse named material.
pub(crate) fn push_material(line: &mut Vec<u8>, syntax: Syntax, name: &str, rgb: Vec3) {
    let (kind, param) = match syntax {
        Syntax::V3 => ("matte", "rgb Kd"),
        Syntax::V4 => ("diffuse", "rgb reflectance"),
    };
    line.extend_from_slice(
        format!(
            "MakeNamedMaterial \"{name}\"\n    \"string type\" [ \"{kind}\" ]\n    \"{param}\" [ "
        )
        .as_bytes(),
    );
    push_vec(line, rgb, 4);
    line.extend_from_slice(b" ]\n");
}

/// Decimals for the linear part: ≥ 6, more for small scales so tiny
/// instances (deep sphereflakes, leaves) keep ~6 significant digits.
fn linear_decimals(m: &Affine) -> u32 {
    let max = m
        .cols
        .iter()
        .flat_map(|c| c.iter())
        .fold(0.0f64, |acc, x| acc.max(x.abs()));
    if max <= 0.0 {
        return 6;
    }
    (6 - max.log10().floor() as i32).clamp(6, 9) as u32
}

/// pbrt's `Transform [16]` is column-major: the images of x, y, z, then the
/// translation, each followed by its homogeneous 0 or 1.
pub(crate) fn push_transform_values(line: &mut Vec<u8>, m: &Affine, translation_decimals: u32) {
    let d = linear_decimals(m);
    for col in &m.cols {
        for &x in col {
            push_fixed(line, x, d);
            line.push(b' ');
        }
        line.extend_from_slice(b"0 ");
    }
    for &x in &m.translation {
        push_fixed(line, x, translation_decimals);
        line.push(b' ');
    }
    line.push(b'1');
}

/// One Moana-style placement line:
/// `AttributeBegin Transform [...] ObjectInstance "name" AttributeEnd`.
pub(crate) fn push_instance(
    line: &mut Vec<u8>,
    parent_from_object: &Affine,
    name: &str,
    translation_decimals: u32,
) {
    line.extend_from_slice(b"AttributeBegin Transform [ ");
    push_transform_values(line, parent_from_object, translation_decimals);
    line.extend_from_slice(b" ] ObjectInstance \"");
    line.extend_from_slice(name.as_bytes());
    line.extend_from_slice(b"\" AttributeEnd\n");
}

#[cfg(test)]
mod tests;
