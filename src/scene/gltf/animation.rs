//! glTF animations sampled at one instant: each channel's keyframes (times, values and
//! interpolation) read and checked, then evaluated at the time asked for, giving the nodes'
//! translations, rotations, scales and morph weights at that instant (a [`Pose`]).
//!
//! The three interpolations of the specification (glTF 2.0, section 3.11 and its appendix C):
//! `STEP` holds a keyframe's value until the next; `LINEAR` interpolates linearly, rotations
//! by spherical linear interpolation along the shorter arc; `CUBICSPLINE` is the cubic Hermite
//! spline through the keyframes with the file's in- and out-tangents (scaled by the keyframe
//! interval), rotations normalised after. Before the first keyframe a channel holds its first
//! value, after the last its last. Every animation of the file plays at once; where two
//! animate the same property of a node, the first in the file wins, with a warning.

use glam::{DQuat, DVec3};

use super::*;

/// What a channel animates.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum Path {
    Translation,
    Rotation,
    Scale,
    Weights,
}

/// The interpolations of the specification.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interpolation {
    /// The value of the keyframe at or before the time.
    Step,
    /// Linear (spherical for rotations) between the keyframes around the time.
    Linear,
    /// Cubic Hermite spline with the file's tangents.
    CubicSpline,
}

/// One channel's keyframes: `times` strictly increasing, and per keyframe `width` values
/// (three, four, or the morph target count), or for a cubic spline three such groups: the
/// in-tangent, the value and the out-tangent.
#[derive(Clone, Debug, PartialEq)]
pub struct Keyframes {
    /// Keyframe times in seconds.
    pub times: Vec<f32>,
    /// The values, keyframe after keyframe.
    pub values: Vec<f32>,
    /// Values per element (3 for a translation or scale, 4 for a rotation, the morph target
    /// count for weights).
    pub width: usize,
    /// How to go from one keyframe to the next.
    pub interpolation: Interpolation,
}

impl Keyframes {
    /// The channel's value at time `t` (seconds), `width` numbers; a rotation (`width` 4,
    /// `rotation` true) interpolated along the shorter arc and normalised.
    pub fn sample(&self, t: f64, rotation: bool) -> Vec<f64> {
        let w = self.width;
        let n = self.times.len();
        let cubic = self.interpolation == Interpolation::CubicSpline;
        // Group `g` of keyframe `k`: a cubic spline's keyframe holds three (in-tangent, value,
        // out-tangent), the others one.
        let per = if cubic { 3 } else { 1 };
        let group = |k: usize, g: usize| -> Vec<f64> {
            let at = (per * k + g) * w;
            self.values[at..at + w]
                .iter()
                .map(|&v| f64::from(v))
                .collect()
        };
        // The value of keyframe `k`.
        let value = |k: usize| group(k, per / 2);
        let first = f64::from(self.times[0]);
        if n == 1 || t <= first {
            return finish(value(0), rotation);
        }
        if t >= f64::from(self.times[n - 1]) {
            return finish(value(n - 1), rotation);
        }
        // The keyframe at or before `t` (`times[0] < t < times[n - 1]` here).
        let k = self.times.partition_point(|&x| f64::from(x) <= t) - 1;
        let (t0, t1) = (f64::from(self.times[k]), f64::from(self.times[k + 1]));
        let dt = t1 - t0;
        let s = (t - t0) / dt;
        let out = match self.interpolation {
            Interpolation::Step => value(k),
            Interpolation::Linear if rotation => {
                let q = |v: Vec<f64>| DQuat::from_xyzw(v[0], v[1], v[2], v[3]).normalize();
                let r = q(value(k)).slerp(q(value(k + 1)), s);
                vec![r.x, r.y, r.z, r.w]
            }
            Interpolation::Linear => {
                let (a, b) = (value(k), value(k + 1));
                a.iter().zip(&b).map(|(a, b)| a + (b - a) * s).collect()
            }
            Interpolation::CubicSpline => {
                let (p0, b0) = (group(k, 1), group(k, 2));
                let (a1, p1) = (group(k + 1, 0), group(k + 1, 1));
                let (s2, s3) = (s * s, s * s * s);
                let h00 = 2.0 * s3 - 3.0 * s2 + 1.0;
                let h10 = s3 - 2.0 * s2 + s;
                let h01 = -2.0 * s3 + 3.0 * s2;
                let h11 = s3 - s2;
                (0..w)
                    .map(|i| h00 * p0[i] + h10 * dt * b0[i] + h01 * p1[i] + h11 * dt * a1[i])
                    .collect()
            }
        };
        finish(out, rotation)
    }

    /// The time of the last keyframe.
    pub fn end(&self) -> f32 {
        self.times.last().copied().unwrap_or(0.0)
    }
}

/// A rotation's four numbers normalised (a zero quaternion left as the identity).
fn finish(mut v: Vec<f64>, rotation: bool) -> Vec<f64> {
    if rotation {
        let q = DQuat::from_xyzw(v[0], v[1], v[2], v[3]);
        let len = q.length();
        let q = if len > 0.0 && len.is_finite() {
            q / len
        } else {
            DQuat::IDENTITY
        };
        v = vec![q.x, q.y, q.z, q.w];
    }
    v
}

/// The nodes' animated properties at one instant; a property no channel animates is absent
/// (the node's own value stands).
#[derive(Clone, Debug, Default, PartialEq)]
pub(super) struct Pose {
    translation: HashMap<usize, DVec3>,
    rotation: HashMap<usize, DQuat>,
    scale: HashMap<usize, DVec3>,
    weights: HashMap<usize, Vec<f32>>,
}

impl Pose {
    /// Node `index`'s local transform: its translation, rotation and scale, each the animated
    /// one where a channel animates it, else the node's own (a node given by a matrix,
    /// unanimated, keeps its matrix exactly).
    pub(super) fn local(&self, index: usize, node: &::gltf::Node) -> DMat4 {
        let animated = self.translation.contains_key(&index)
            || self.rotation.contains_key(&index)
            || self.scale.contains_key(&index);
        if !animated {
            return DMat4::from_cols_array_2d(&node.transform().matrix().map(|c| c.map(f64::from)));
        }
        let (t, r, s) = node.transform().decomposed();
        let t = self
            .translation
            .get(&index)
            .copied()
            .unwrap_or(DVec3::from(t.map(f64::from)));
        let r = self.rotation.get(&index).copied().unwrap_or_else(|| {
            let [x, y, z, w] = r.map(f64::from);
            DQuat::from_xyzw(x, y, z, w)
        });
        let s = self
            .scale
            .get(&index)
            .copied()
            .unwrap_or(DVec3::from(s.map(f64::from)));
        DMat4::from_scale_rotation_translation(s, r, t)
    }

    /// Node `index`'s animated morph weights, if a channel animates them.
    pub(super) fn weights(&self, index: usize) -> Option<&[f32]> {
        self.weights.get(&index).map(Vec::as_slice)
    }
}

/// Reads a scalar accessor (float, or normalised integers where `types` allows them) as
/// floats; the accessor must have been checked.
fn read_scalars<'a, 's, F>(acc: &::gltf::Accessor<'a>, get: F) -> Option<Vec<f32>>
where
    F: Clone + Fn(::gltf::Buffer<'a>) -> Option<&'s [u8]>,
{
    use ::gltf::accessor::Iter;
    let norm = acc.normalized();
    let int = move |c: f32, max: f32| if norm { (c / max).max(-1.0) } else { c };
    Some(match acc.data_type() {
        DataType::F32 => Iter::<f32>::new(acc.clone(), get)?.collect(),
        DataType::I8 => Iter::<i8>::new(acc.clone(), get)?
            .map(|c| int(f32::from(c), 127.0))
            .collect(),
        DataType::U8 => Iter::<u8>::new(acc.clone(), get)?
            .map(|c| int(f32::from(c), 255.0))
            .collect(),
        DataType::I16 => Iter::<i16>::new(acc.clone(), get)?
            .map(|c| int(f32::from(c), 32767.0))
            .collect(),
        DataType::U16 => Iter::<u16>::new(acc.clone(), get)?
            .map(|c| int(f32::from(c), 65535.0))
            .collect(),
        DataType::U32 => return None,
    })
}

/// Component types of animated rotations and weights: floats or normalised integers.
const NORMALIZED: &[DataType] = &[
    DataType::F32,
    DataType::I8,
    DataType::U8,
    DataType::I16,
    DataType::U16,
];

impl Loader<'_> {
    /// Every animation's channels at time `t` (seconds); also the time of the last keyframe
    /// of any channel (the length of the file's animation).
    pub(super) fn pose_at(&mut self, doc: &::gltf::Document, t: f64) -> Result<(Pose, f32)> {
        let mut pose = Pose::default();
        let mut seen: HashMap<(usize, Path), usize> = HashMap::new();
        let mut end = 0.0f32;
        for anim in doc.animations() {
            for (c, channel) in anim.channels().enumerate() {
                let at = format!("{}: animations[{}].channels[{c}]", self.name, anim.index());
                let node = channel.target().node().index();
                let path = match channel.target().property() {
                    ::gltf::animation::Property::Translation => Path::Translation,
                    ::gltf::animation::Property::Rotation => Path::Rotation,
                    ::gltf::animation::Property::Scale => Path::Scale,
                    ::gltf::animation::Property::MorphTargetWeights => Path::Weights,
                };
                if let Some(first) = seen.get(&(node, path)) {
                    self.warnings.push(format!(
                        "{at}: nodes[{node}]'s {path:?} is animated by animations[{first}] too; animations[{first}]'s is played"
                    ));
                    continue;
                }
                seen.insert((node, path), anim.index());
                let width = match path {
                    Path::Translation | Path::Scale => 3,
                    Path::Rotation => 4,
                    Path::Weights => self.morph_targets(node),
                };
                if width == 0 {
                    self.warnings.push(format!(
                        "{at}: animates the morph weights of nodes[{node}], whose mesh has no morph targets; left out"
                    ));
                    continue;
                }
                let keys = self.keyframes(&at, &channel.sampler(), path, width)?;
                end = end.max(keys.end());
                let v = keys.sample(t, path == Path::Rotation);
                match path {
                    Path::Translation => {
                        pose.translation.insert(node, DVec3::new(v[0], v[1], v[2]));
                    }
                    Path::Scale => {
                        pose.scale.insert(node, DVec3::new(v[0], v[1], v[2]));
                    }
                    Path::Rotation => {
                        pose.rotation
                            .insert(node, DQuat::from_xyzw(v[0], v[1], v[2], v[3]));
                    }
                    Path::Weights => {
                        pose.weights
                            .insert(node, v.iter().map(|&w| w as f32).collect());
                    }
                }
            }
        }
        Ok((pose, end))
    }

    /// How long the file's animations run: the latest keyframe time of any sampler (read from
    /// the input accessor's `max`, which the specification asks for, else from its values).
    pub(super) fn length(&self, doc: &::gltf::Document) -> Result<f32> {
        let mut end = 0.0f32;
        for anim in doc.animations() {
            for (i, sampler) in anim.samplers().enumerate() {
                let input = sampler.input();
                let max = input
                    .max()
                    .and_then(|m| m.as_array().and_then(|a| a.first()?.as_f64()));
                let last = match max {
                    Some(m) => m as f32,
                    None => {
                        let at =
                            format!("{}: animations[{}].samplers[{i}]", self.name, anim.index());
                        self.check_accessor(
                            &at,
                            "sampler input",
                            &input,
                            &[DataType::F32],
                            Dimensions::Scalar,
                        )?;
                        let buffers = self.buffers;
                        let get = |b: ::gltf::Buffer| {
                            buffers.get(b.index()).and_then(|d| d.as_deref().ok())
                        };
                        read_scalars(&input, get)
                            .and_then(|t| t.last().copied())
                            .ok_or_else(|| anyhow!("{at}: sampler input cannot be read"))?
                    }
                };
                if last.is_finite() {
                    end = end.max(last);
                }
            }
        }
        Ok(end)
    }

    /// The number of morph targets of node `node`'s mesh (its first primitive's: the
    /// specification asks every primitive of a mesh to have as many).
    fn morph_targets(&self, node: usize) -> usize {
        self.nodes
            .get(node)
            .and_then(|n| n.mesh())
            .and_then(|m| m.primitives().next())
            .map_or(0, |p| p.morph_targets().count())
    }

    /// A sampler's keyframes, checked: float times, strictly increasing and finite; as many
    /// values as the interpolation needs, of the type the property allows, finite.
    fn keyframes(
        &self,
        at: &str,
        sampler: &::gltf::animation::Sampler,
        path: Path,
        width: usize,
    ) -> Result<Keyframes> {
        let input = sampler.input();
        let output = sampler.output();
        self.check_accessor(
            at,
            "sampler input",
            &input,
            &[DataType::F32],
            Dimensions::Scalar,
        )?;
        let (types, dims) = match path {
            Path::Translation | Path::Scale => (&[DataType::F32][..], Dimensions::Vec3),
            Path::Rotation => (NORMALIZED, Dimensions::Vec4),
            Path::Weights => (NORMALIZED, Dimensions::Scalar),
        };
        self.check_accessor(at, "sampler output", &output, types, dims)?;
        let buffers = self.buffers;
        let get = |b: ::gltf::Buffer| buffers.get(b.index()).and_then(|d| d.as_deref().ok());
        let times = read_scalars(&input, get)
            .ok_or_else(|| anyhow!("{at}: sampler input cannot be read"))?;
        if let Some(i) = times.iter().position(|t| !t.is_finite()) {
            bail!("{at}: keyframe time {i} is not finite");
        }
        if let Some(i) = times.windows(2).position(|w| w[1] <= w[0]) {
            bail!(
                "{at}: keyframe times must increase: time {} is {} after {}",
                i + 1,
                times[i + 1],
                times[i]
            );
        }
        let values: Vec<f32> = if dims == Dimensions::Scalar {
            read_scalars(&output, get)
        } else {
            read_floats(&output, get).map(|v| {
                v.into_iter()
                    .flat_map(|e| e.into_iter().take(dims.multiplicity()))
                    .collect()
            })
        }
        .ok_or_else(|| anyhow!("{at}: sampler output cannot be read"))?;
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            bail!("{at}: sampler output value {i} is not finite");
        }
        let interpolation = match sampler.interpolation() {
            ::gltf::animation::Interpolation::Step => Interpolation::Step,
            ::gltf::animation::Interpolation::Linear => Interpolation::Linear,
            ::gltf::animation::Interpolation::CubicSpline => Interpolation::CubicSpline,
        };
        let per_key = if interpolation == Interpolation::CubicSpline {
            3 * width
        } else {
            width
        };
        if values.len() != times.len() * per_key {
            bail!(
                "{at}: {} keyframe(s) of {interpolation:?} need {} output value(s), the sampler has {}",
                times.len(),
                times.len() * per_key,
                values.len()
            );
        }
        Ok(Keyframes {
            times,
            values,
            width,
            interpolation,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn keys(times: &[f32], values: &[f32], width: usize, i: Interpolation) -> Keyframes {
        Keyframes {
            times: times.to_vec(),
            values: values.to_vec(),
            width,
            interpolation: i,
        }
    }

    #[test]
    fn step_holds_each_value_until_the_next_keyframe() {
        let k = keys(&[0.0, 1.0, 2.0], &[1.0, 5.0, 9.0], 1, Interpolation::Step);
        assert_eq!(k.sample(-1.0, false), [1.0]);
        assert_eq!(k.sample(0.99, false), [1.0]);
        assert_eq!(k.sample(1.0, false), [5.0]);
        assert_eq!(k.sample(1.5, false), [5.0]);
        assert_eq!(k.sample(7.0, false), [9.0]);
    }

    #[test]
    fn linear_interpolates_between_keyframes() {
        let k = keys(
            &[1.0, 3.0],
            &[0.0, 2.0, 4.0, 10.0, 2.0, 0.0],
            3,
            Interpolation::Linear,
        );
        assert_eq!(k.sample(2.0, false), [5.0, 2.0, 2.0]);
        assert_eq!(k.sample(2.5, false), [7.5, 2.0, 1.0]);
        assert_eq!(k.sample(0.0, false), [0.0, 2.0, 4.0]);
    }

    /// A quarter turn about z sampled half way is an eighth of a turn; a quaternion and its
    /// negation are the same rotation, and the shorter arc is taken.
    #[test]
    fn rotations_take_the_shorter_arc() {
        let h = std::f32::consts::FRAC_1_SQRT_2;
        let k = keys(
            &[0.0, 1.0],
            &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, -h, -h],
            4,
            Interpolation::Linear,
        );
        let v = k.sample(0.5, true);
        let q = DQuat::from_xyzw(v[0], v[1], v[2], v[3]);
        let want = DQuat::from_rotation_z(std::f64::consts::FRAC_PI_4);
        assert!(q.dot(want).abs() > 1.0 - 1e-7, "{q:?}");
    }

    /// The Hermite basis by hand: p(s) = (2s^3 - 3s^2 + 1) p0 + (s^3 - 2s^2 + s) dt b0 +
    /// (-2s^3 + 3s^2) p1 + (s^3 - s^2) dt a1.
    #[test]
    fn cubic_splines_follow_the_hermite_basis() {
        // Keyframes at 0 and 2: (in, value, out) = (9, 1, 0.5) and (-1, 3, 7); a1 = -1.
        let k = keys(
            &[0.0, 2.0],
            &[9.0, 1.0, 0.5, -1.0, 3.0, 7.0],
            1,
            Interpolation::CubicSpline,
        );
        let s: f64 = 0.25;
        let dt = 2.0;
        let want = (2.0 * s.powi(3) - 3.0 * s * s + 1.0) * 1.0
            + (s.powi(3) - 2.0 * s * s + s) * dt * 0.5
            + (-2.0 * s.powi(3) + 3.0 * s * s) * 3.0
            - (s.powi(3) - s * s) * dt;
        assert!((k.sample(0.5, false)[0] - want).abs() < 1e-12);
        assert_eq!(k.sample(0.0, false), [1.0]);
        assert_eq!(k.sample(2.0, false), [3.0]);
    }
}
