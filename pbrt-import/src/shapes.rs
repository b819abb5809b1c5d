//! Building geometry from `Shape` parameters (everything but `plymesh`).

use crate::events::{Curve, Mesh};
use crate::params::{ParamList, Values};

/// Move a float array out of the list (no copy of the big vector).
fn take_nums(params: &mut ParamList<'_>, name: &str) -> Option<Vec<f32>> {
    let i = params
        .params
        .iter()
        .position(|p| p.name == name && matches!(p.values, Values::Nums(_)))?;
    match params.params.swap_remove(i).values {
        Values::Nums(v) => Some(v),
        _ => None,
    }
}

fn take_ints(params: &mut ParamList<'_>, name: &str) -> Option<Vec<i32>> {
    let i = params
        .params
        .iter()
        .position(|p| p.name == name && matches!(p.values, Values::Ints(_)))?;
    match params.params.swap_remove(i).values {
        Values::Ints(v) => Some(v),
        _ => None,
    }
}

/// `v` (of a multiple of `N` values) as `N`-tuples, in its own allocation where it can be
/// (trimmed to its length, then reinterpreted): a Moana-scale parse's vertex arrays were
/// copied here, fresh pages for every vertex (issue 48 item 1). Copied when the allocator
/// cannot trim in place.
fn to_tuples<const N: usize>(mut v: Vec<f32>) -> Vec<[f32; N]>
where
    [f32; N]: bytemuck::Pod,
{
    v.shrink_to_fit();
    bytemuck::allocation::try_cast_vec(v).unwrap_or_else(|(_, v)| {
        v.chunks_exact(N)
            .map(|c| std::array::from_fn(|k| c[k]))
            .collect()
    })
}

fn to3(v: Vec<f32>) -> Vec<[f32; 3]> {
    to_tuples(v)
}

fn to2(v: Vec<f32>) -> Vec<[f32; 2]> {
    to_tuples(v)
}

/// Shared vertex attributes: `P`, `N`, `uv`/`st`. Mismatched optional arrays are dropped
/// with a message in `notes`.
fn vertices(params: &mut ParamList<'_>, notes: &mut Vec<String>) -> Result<Mesh, String> {
    let p = take_nums(params, "P").ok_or("missing \"P\"")?;
    if p.len() % 3 != 0 {
        return Err(format!("\"P\" has {} values, not a multiple of 3", p.len()));
    }
    let positions = to3(p);
    let n_verts = positions.len();
    let normals = take_nums(params, "N").and_then(|n| {
        if n.len() == n_verts * 3 {
            Some(to3(n))
        } else {
            notes.push(format!(
                "\"N\" has {} values for {n_verts} vertices; ignored",
                n.len()
            ));
            None
        }
    });
    let uv = take_nums(params, "uv").or_else(|| take_nums(params, "st"));
    let uvs = uv.and_then(|uv| {
        if uv.len() == n_verts * 2 {
            Some(to2(uv))
        } else {
            notes.push(format!(
                "\"uv\" has {} values for {n_verts} vertices; ignored",
                uv.len()
            ));
            None
        }
    });
    Ok(Mesh {
        positions,
        normals,
        uvs,
        indices: Vec::new(),
        face_ids: None,
    })
}

/// pbrt's `faceIndices` (one per triangle or patch, `count` of them); another length is
/// dropped with a message in `notes`.
fn face_indices(
    params: &mut ParamList<'_>,
    count: usize,
    notes: &mut Vec<String>,
) -> Option<Vec<u32>> {
    let raw = take_ints(params, "faceIndices")?;
    if raw.len() != count || raw.iter().any(|&f| f < 0) {
        notes.push(format!(
            "\"faceIndices\" has {} values for {count} faces (or a negative one); ignored",
            raw.len()
        ));
        return None;
    }
    Some(raw.into_iter().map(|f| f as u32).collect())
}

fn checked_indices(raw: Vec<i32>, n_verts: usize) -> Result<Vec<u32>, String> {
    // One pass for the range (branch-free, so it vectorizes), then the conversion reuses
    // the allocation; the first offending index is looked for only when there is one.
    let (lo, hi) = raw
        .iter()
        .fold((i32::MAX, i32::MIN), |(lo, hi), &i| (lo.min(i), hi.max(i)));
    if !raw.is_empty() && (lo < 0 || hi as usize >= n_verts) {
        let i = raw
            .iter()
            .find(|&&i| i < 0 || i as usize >= n_verts)
            .copied()
            .unwrap_or(lo);
        return Err(format!(
            "vertex index {i} out of range ({n_verts} vertices)"
        ));
    }
    Ok(raw.into_iter().map(|i| i as u32).collect())
}

/// `trianglemesh` (and `loopsubdiv`'s base cage).
pub(crate) fn triangle_mesh(
    params: &mut ParamList<'_>,
    notes: &mut Vec<String>,
) -> Result<Mesh, String> {
    let mut mesh = vertices(params, notes)?;
    let n = mesh.positions.len();
    mesh.indices = match take_ints(params, "indices") {
        Some(raw) => checked_indices(raw, n)?,
        None if n == 3 => vec![0, 1, 2],
        None => return Err("missing \"indices\"".into()),
    };
    if mesh.indices.len() % 3 != 0 {
        return Err(format!(
            "{} indices, not a multiple of 3",
            mesh.indices.len()
        ));
    }
    mesh.face_ids = face_indices(params, mesh.indices.len() / 3, notes);
    Ok(mesh)
}

/// `bilinearmesh`: each patch `v00 v10 v01 v11` becomes two triangles.
pub(crate) fn bilinear_mesh(
    params: &mut ParamList<'_>,
    notes: &mut Vec<String>,
) -> Result<Mesh, String> {
    let mut mesh = vertices(params, notes)?;
    let n = mesh.positions.len();
    let quads = match take_ints(params, "indices") {
        Some(raw) => checked_indices(raw, n)?,
        None if n == 4 => vec![0, 1, 2, 3],
        None => return Err("missing \"indices\"".into()),
    };
    if quads.len() % 4 != 0 {
        return Err(format!("{} indices, not a multiple of 4", quads.len()));
    }
    mesh.indices = quads
        .chunks_exact(4)
        .flat_map(|q| [q[0], q[1], q[3], q[0], q[3], q[2]])
        .collect();
    // A patch's triangles are its Ptex face's halves: (v00 v10 v11) and (v00 v11 v01).
    let faces = face_indices(params, quads.len() / 4, notes)
        .unwrap_or_else(|| (0..(quads.len() / 4) as u32).collect());
    mesh.face_ids = Some(
        faces
            .iter()
            .flat_map(|&f| [f, f | crate::events::FACE_SECOND_HALF])
            .collect(),
    );
    Ok(mesh)
}

/// A grid of `rings+1` x `segs+1` vertices from `f(u, v) -> (position, normal)`.
fn grid(segs: u32, rings: u32, f: impl Fn(f32, f32) -> ([f32; 3], [f32; 3])) -> Mesh {
    let mut m = Mesh {
        normals: Some(Vec::new()),
        uvs: Some(Vec::new()),
        ..Default::default()
    };
    for j in 0..=rings {
        for i in 0..=segs {
            let (u, v) = (i as f32 / segs as f32, j as f32 / rings as f32);
            let (p, n) = f(u, v);
            m.positions.push(p);
            if let Some(ns) = m.normals.as_mut() {
                ns.push(n);
            }
            if let Some(uv) = m.uvs.as_mut() {
                uv.push([u, v]);
            }
        }
    }
    let w = segs + 1;
    for j in 0..rings {
        for i in 0..segs {
            let a = j * w + i;
            m.indices
                .extend_from_slice(&[a, a + 1, a + w + 1, a, a + w + 1, a + w]);
        }
    }
    m
}

/// A float parameter that must be finite: NaN or infinite radii and heights would make
/// non-finite geometry (and NaN bounds panic `f32::clamp`).
fn finite(params: &ParamList<'_>, name: &str, default: f32) -> Result<f32, String> {
    let v = params.float(name).unwrap_or(default);
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!("\"{name}\" is {v}, not a finite number"))
    }
}

fn phi_max(params: &ParamList<'_>) -> Result<f32, String> {
    Ok(finite(params, "phimax", 360.0)?
        .clamp(0.0, 360.0)
        .to_radians())
}

/// `sphere` (radius, zmin, zmax, phimax).
pub(crate) fn sphere(params: &ParamList<'_>, segs: u32) -> Result<Mesh, String> {
    let r = finite(params, "radius", 1.0)?;
    let zmin = finite(params, "zmin", -r)?.clamp(-r.abs(), r.abs());
    let zmax = finite(params, "zmax", r)?.clamp(-r.abs(), r.abs());
    // r == 0 gives 0/0 = NaN here; clamp passes NaN through, and a zero-radius sphere's
    // vertices are all at the origin (n * r) whatever theta is.
    let cos_theta = |z: f32| {
        if r == 0.0 {
            1.0
        } else {
            (z / r).clamp(-1.0, 1.0)
        }
    };
    let theta0 = cos_theta(zmin).acos();
    let theta1 = cos_theta(zmax).acos();
    let phimax = phi_max(params)?;
    Ok(grid(segs, (segs / 2).max(2), |u, v| {
        let phi = u * phimax;
        let theta = theta0 + (theta1 - theta0) * v;
        let n = [
            theta.sin() * phi.cos(),
            theta.sin() * phi.sin(),
            theta.cos(),
        ];
        ([n[0] * r, n[1] * r, n[2] * r], n)
    }))
}

/// `disk` (height, radius, innerradius, phimax).
pub(crate) fn disk(params: &ParamList<'_>, segs: u32) -> Result<Mesh, String> {
    let h = finite(params, "height", 0.0)?;
    let r = finite(params, "radius", 1.0)?;
    let ri = finite(params, "innerradius", 0.0)?;
    let phimax = phi_max(params)?;
    Ok(grid(segs, 1, |u, v| {
        let phi = u * phimax;
        let rad = r + (ri - r) * v;
        ([rad * phi.cos(), rad * phi.sin(), h], [0.0, 0.0, 1.0])
    }))
}

/// `cylinder` (radius, zmin, zmax, phimax).
pub(crate) fn cylinder(params: &ParamList<'_>, segs: u32) -> Result<Mesh, String> {
    let r = finite(params, "radius", 1.0)?;
    let zmin = finite(params, "zmin", -1.0)?;
    let zmax = finite(params, "zmax", 1.0)?;
    let phimax = phi_max(params)?;
    Ok(grid(segs, 1, |u, v| {
        let phi = u * phimax;
        (
            [r * phi.cos(), r * phi.sin(), zmin + (zmax - zmin) * v],
            [phi.cos(), phi.sin(), 0.0],
        )
    }))
}

/// `curve`.
pub(crate) fn curve(params: &mut ParamList<'_>) -> Result<Curve, String> {
    let p = take_nums(params, "P").ok_or("missing \"P\"")?;
    let degree = params.int("degree").unwrap_or(3);
    if !(degree == 2 || degree == 3) {
        return Err(format!("curve degree {degree} (must be 2 or 3)"));
    }
    let basis = params.string("basis").unwrap_or("bezier").to_owned();
    let n_cp = p.len() / 3;
    let ok = match basis.as_str() {
        "bezier" => n_cp > degree as usize && (n_cp - 1 - degree as usize) % degree as usize == 0,
        "bspline" => n_cp > degree as usize,
        other => return Err(format!("unknown curve basis `{other}`")),
    };
    if !ok || p.len() % 3 != 0 {
        return Err(format!(
            "{n_cp} control points do not fit a degree {degree} {basis} curve"
        ));
    }
    let width = params.float("width").unwrap_or(1.0);
    let normals = take_nums(params, "N").map(to3);
    Ok(Curve {
        basis,
        curve_type: params.string("type").unwrap_or("flat").to_owned(),
        degree: degree as u32,
        control_points: to3(p),
        width0: params.float("width0").unwrap_or(width),
        width1: params.float("width1").unwrap_or(width),
        normals,
    })
}

/// Sanity check used by tests: every index is in range.
#[cfg(test)]
pub(crate) fn valid(m: &Mesh) -> bool {
    m.indices.len() % 3 == 0 && m.indices.iter().all(|&i| (i as usize) < m.positions.len())
}

#[cfg(test)]
mod tests;
