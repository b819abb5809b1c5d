//! Minimal f64 affine transforms: all this crate needs to compose and print
//! pbrt `Transform [16]` matrices (keeps the crate free of a math dependency).

pub(crate) type Vec3 = [f64; 3];

pub(crate) fn add(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

pub(crate) fn scale(a: Vec3, s: f64) -> Vec3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

pub(crate) fn cross(a: Vec3, b: Vec3) -> Vec3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

pub(crate) fn dot(a: Vec3, b: Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub(crate) fn normalize(a: Vec3) -> Vec3 {
    let len = dot(a, a).sqrt();
    if len > 0.0 {
        scale(a, 1.0 / len)
    } else {
        [0.0, 1.0, 0.0]
    }
}

/// `parent_from_child`: p' = cols · p + translation. `cols[i]` is the image of axis i.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Affine {
    pub(crate) cols: [Vec3; 3],
    pub(crate) translation: Vec3,
}

impl Affine {
    pub(crate) const IDENTITY: Affine = Affine {
        cols: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        translation: [0.0, 0.0, 0.0],
    };

    pub(crate) fn translation(t: Vec3) -> Affine {
        Affine {
            translation: t,
            ..Affine::IDENTITY
        }
    }

    pub(crate) fn uniform_scale(s: f64) -> Affine {
        Affine {
            cols: [[s, 0.0, 0.0], [0.0, s, 0.0], [0.0, 0.0, s]],
            translation: [0.0; 3],
        }
    }

    /// Rotation by `angle_rad` about the unit vector `axis` (Rodrigues).
    pub(crate) fn rotation(axis: Vec3, angle_rad: f64) -> Affine {
        let [x, y, z] = normalize(axis);
        let (s, c) = angle_rad.sin_cos();
        let t = 1.0 - c;
        Affine {
            cols: [
                [t * x * x + c, t * x * y + s * z, t * x * z - s * y],
                [t * x * y - s * z, t * y * y + c, t * y * z + s * x],
                [t * x * z + s * y, t * y * z - s * x, t * z * z + c],
            ],
            translation: [0.0; 3],
        }
    }

    pub(crate) fn rotation_y(angle_rad: f64) -> Affine {
        Affine::rotation([0.0, 1.0, 0.0], angle_rad)
    }

    /// The rotation taking unit `from` onto unit `to` along the shortest arc.
    pub(crate) fn rotation_arc(from: Vec3, to: Vec3) -> Affine {
        let axis = cross(from, to);
        let sin = dot(axis, axis).sqrt();
        let cos = dot(from, to);
        if sin < 1e-12 {
            if cos > 0.0 {
                return Affine::IDENTITY;
            }
            // Opposite: any perpendicular axis works.
            let perp = if from[0].abs() < 0.9 {
                [1.0, 0.0, 0.0]
            } else {
                [0.0, 0.0, 1.0]
            };
            return Affine::rotation(cross(from, perp), std::f64::consts::PI);
        }
        Affine::rotation(axis, sin.atan2(cos))
    }

    /// `self ∘ rhs`: apply `rhs` first.
    pub(crate) fn mul(&self, rhs: &Affine) -> Affine {
        Affine {
            cols: [
                self.transform_vector(rhs.cols[0]),
                self.transform_vector(rhs.cols[1]),
                self.transform_vector(rhs.cols[2]),
            ],
            translation: self.transform_point(rhs.translation),
        }
    }

    pub(crate) fn transform_vector(&self, v: Vec3) -> Vec3 {
        add(
            add(scale(self.cols[0], v[0]), scale(self.cols[1], v[1])),
            scale(self.cols[2], v[2]),
        )
    }

    pub(crate) fn transform_point(&self, p: Vec3) -> Vec3 {
        add(self.transform_vector(p), self.translation)
    }
}

#[cfg(test)]
mod tests;
