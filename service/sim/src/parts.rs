//! Body parts of the ground truth: every base-mesh vertex belongs to the part of the bone
//! that moves it most (MakeHuman's default rig and weights), and a point of the true surface
//! (body or garment) to the part of the nearest body vertex. What `volcap eval` reports
//! error per part with (hands and feet are where a reconstruction fails first).

use crate::assets::HumanAssets;
use glam::{DVec3, Vec3};
use kiddo::{KdTree, SquaredEuclidean};

/// A body part.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Part {
    Head,
    Torso,
    Arms,
    Hands,
    Legs,
    Feet,
}

impl Part {
    pub const ALL: [Part; 6] = [
        Part::Head,
        Part::Torso,
        Part::Arms,
        Part::Hands,
        Part::Legs,
        Part::Feet,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Part::Head => "head",
            Part::Torso => "torso",
            Part::Arms => "arms",
            Part::Hands => "hands",
            Part::Legs => "legs",
            Part::Feet => "feet",
        }
    }

    /// The part a bone of the default rig moves (by its name: `wrist.L`, `finger2-3.R`,
    /// `upperleg01.L`, ...); the spine, pelvis, clavicles, breasts and root are the torso.
    pub fn of_bone(name: &str) -> Part {
        let stem = name.split('.').next().unwrap_or(name);
        let starts = |p: &[&str]| p.iter().any(|x| stem.starts_with(x));
        if starts(&["finger", "metacarpal", "wrist"]) {
            Part::Hands
        } else if starts(&["foot", "toe"]) {
            Part::Feet
        } else if starts(&["shoulder", "upperarm", "lowerarm"]) {
            Part::Arms
        } else if starts(&["upperleg", "lowerleg"]) {
            Part::Legs
        } else if starts(&[
            "head",
            "neck",
            "jaw",
            "eye",
            "oculi",
            "orbicularis",
            "oris",
            "risorius",
            "levator",
            "temporalis",
            "tongue",
            "special",
        ]) {
            Part::Head
        } else {
            Part::Torso
        }
    }
}

/// The part of every base-mesh vertex: its most weighted bone's.
pub fn vertex_parts(assets: &HumanAssets) -> Vec<Part> {
    assets
        .weights
        .iter()
        .map(|inf| {
            let best = inf
                .iter()
                .filter(|(_, w)| *w > 0.0)
                .max_by(|a, b| a.1.total_cmp(&b.1));
            match best.and_then(|(b, _)| assets.bones.get(*b as usize)) {
                Some(bone) => Part::of_bone(&bone.name),
                None => Part::Torso,
            }
        })
        .collect()
}

/// Labels points of a posed subject's surface: the part of the nearest vertex of its body
/// (the vertices the body's triangles use; helper geometry left out).
pub struct PartLabeler {
    tree: KdTree<f64, 3>,
    parts: Vec<Part>,
}

impl PartLabeler {
    /// `posed`: the subject's posed base vertices (world), `body_tris`: the body's
    /// triangles, `vertex_parts`: [`vertex_parts`] of the same assets.
    pub fn new(posed: &[Vec3], body_tris: &[[u32; 3]], vertex_parts: &[Part]) -> Self {
        let mut used = vec![false; posed.len()];
        for t in body_tris {
            for &i in t {
                if let Some(u) = used.get_mut(i as usize) {
                    *u = true;
                }
            }
        }
        let mut tree: KdTree<f64, 3> = KdTree::with_capacity(posed.len().max(1));
        let mut parts = Vec::new();
        for (i, v) in posed.iter().enumerate() {
            if used[i] && v.is_finite() {
                tree.add(&v.as_dvec3().to_array(), parts.len() as u64);
                parts.push(vertex_parts.get(i).copied().unwrap_or(Part::Torso));
            }
        }
        Self { tree, parts }
    }

    /// The part of the body vertex nearest to `p` (torso when the body is empty).
    pub fn label(&self, p: DVec3) -> Part {
        if self.parts.is_empty() {
            return Part::Torso;
        }
        let n = self.tree.nearest_one::<SquaredEuclidean>(&p.to_array());
        self.parts[n.item as usize]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bone_names_map_to_parts() {
        for (bone, part) in [
            ("wrist.L", Part::Hands),
            ("finger3-2.R", Part::Hands),
            ("metacarpal1.L", Part::Hands),
            ("toe2-3.R", Part::Feet),
            ("foot.L", Part::Feet),
            ("lowerarm02.R", Part::Arms),
            ("shoulder01.L", Part::Arms),
            ("upperleg01.L", Part::Legs),
            ("head", Part::Head),
            ("oris03.L", Part::Head),
            ("neck02", Part::Head),
            ("spine03", Part::Torso),
            ("pelvis.R", Part::Torso),
            ("clavicle.L", Part::Torso),
            ("root", Part::Torso),
        ] {
            assert_eq!(Part::of_bone(bone), part, "{bone}");
        }
    }

    /// On the embedded subject in its rest pose: every part has vertices, the hands are
    /// below the shoulders and farther from the body's axis than the arms on average, the
    /// feet lowest, the head highest; a vertex is labelled with its own part.
    #[test]
    fn parts_sit_where_a_body_has_them() {
        let assets = HumanAssets::embedded().unwrap();
        let vp = vertex_parts(&assets);
        assert_eq!(vp.len(), assets.base.len());
        let verts: Vec<Vec3> = assets.base.iter().map(|v| Vec3::from(*v)).collect();
        let lab = PartLabeler::new(&verts, &assets.body_tris, &vp);
        let mut used = vec![false; verts.len()];
        for t in &assets.body_tris {
            for &i in t {
                used[i as usize] = true;
            }
        }
        let mean = |part: Part| {
            let pts: Vec<Vec3> = verts
                .iter()
                .zip(&vp)
                .zip(&used)
                .filter(|((_, p), u)| **p == part && **u)
                .map(|((v, _), _)| *v)
                .collect();
            assert!(pts.len() > 50, "{part:?}: {} vertices", pts.len());
            let radial = pts.iter().map(|v| v.x.abs()).sum::<f32>() / pts.len() as f32;
            (pts.iter().copied().sum::<Vec3>() / pts.len() as f32, radial)
        };
        let (head, _) = mean(Part::Head);
        let (torso, _) = mean(Part::Torso);
        let (_, arms_x) = mean(Part::Arms);
        let (hands, hands_x) = mean(Part::Hands);
        let (legs, _) = mean(Part::Legs);
        let (feet, _) = mean(Part::Feet);
        assert!(head.y > torso.y && torso.y > legs.y && legs.y > feet.y);
        assert!(
            hands.y < head.y && hands_x > arms_x,
            "hands {hands} at |x| {hands_x} vs arms {arms_x}"
        );
        for (i, v) in verts
            .iter()
            .enumerate()
            .filter(|(i, _)| used[*i])
            .step_by(97)
        {
            assert_eq!(lab.label(v.as_dvec3()), vp[i], "vertex {i}");
        }
    }
}
