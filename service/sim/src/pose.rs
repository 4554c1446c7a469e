//! Poses: static poses from the pack (BVH), and a seeded procedural generator with joint
//! limits for walking, arms raised, crouching, turning, one arm across the body, leaning; the
//! hands at rest or, with [`Hands::Varied`], in drawn wrist and finger poses (`hands.rs`).
//!
//! Rotations are per bone, parent-relative, about mesh-frame axes (y up, the character faces
//! +z, +x is its left): hip/shoulder flexion forward is a negative rotation about x, knee and
//! spine flexion positive about x, abduction of the left arm positive about z.

use crate::assets::HumanAssets;
pub use crate::hands::Hands;
use crate::hands::{HandDraw, HandRig};
use glam::{Mat3, Vec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Deserialize;

/// Procedural motion styles.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Style {
    Walk,
    ArmsRaised,
    Crouch,
    Turn,
    ArmAcross,
    Lean,
}

impl Style {
    pub const ALL: [Style; 6] = [
        Style::Walk,
        Style::ArmsRaised,
        Style::Crouch,
        Style::Turn,
        Style::ArmAcross,
        Style::Lean,
    ];

    /// The name used in scene files (the serde name).
    pub fn name(self) -> &'static str {
        match self {
            Style::Walk => "walk",
            Style::ArmsRaised => "arms-raised",
            Style::Crouch => "crouch",
            Style::Turn => "turn",
            Style::ArmAcross => "arm-across",
            Style::Lean => "lean",
        }
    }
}

/// Joint angles (degrees) the generator drives, before limits.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Angles {
    pub root_yaw: f32,
    pub spine_flex: f32,
    pub spine_side: f32,
    pub neck_flex: f32,
    /// [left, right]
    pub hip_flex: [f32; 2],
    pub knee: [f32; 2],
    pub ankle: [f32; 2],
    pub shoulder_abd: [f32; 2],
    pub shoulder_flex: [f32; 2],
    pub shoulder_across: [f32; 2],
    pub elbow: [f32; 2],
    /// The hands (`hands.rs`): zero at rest.
    pub forearm_twist: [f32; 2],
    pub wrist_flex: [f32; 2],
    pub wrist_dev: [f32; 2],
    pub finger_curl: [f32; 2],
}

/// Joint limits (degrees), (min, max).
pub const LIMITS: [(&str, f32, f32); 14] = [
    ("spine_flex", -20.0, 60.0),
    ("spine_side", -30.0, 30.0),
    ("neck_flex", -40.0, 40.0),
    ("hip_flex", -30.0, 120.0),
    ("knee", 0.0, 140.0),
    ("ankle", -30.0, 40.0),
    ("shoulder_abd", -20.0, 150.0),
    ("shoulder_flex", -50.0, 170.0),
    ("shoulder_across", -10.0, 90.0),
    ("elbow", 0.0, 145.0),
    ("forearm_twist", -85.0, 95.0),
    ("wrist_flex", -60.0, 70.0),
    ("wrist_dev", -20.0, 30.0),
    ("finger_curl", 0.0, 90.0),
];

fn lim(name: &str, v: f32) -> f32 {
    let (_, lo, hi) = LIMITS
        .iter()
        .find(|l| l.0 == name)
        .copied()
        .unwrap_or((name, -180.0, 180.0));
    v.clamp(lo, hi)
}

impl Angles {
    /// Clamp every angle to [`LIMITS`].
    pub fn limited(mut self) -> Self {
        self.spine_flex = lim("spine_flex", self.spine_flex);
        self.spine_side = lim("spine_side", self.spine_side);
        self.neck_flex = lim("neck_flex", self.neck_flex);
        for s in 0..2 {
            self.hip_flex[s] = lim("hip_flex", self.hip_flex[s]);
            self.knee[s] = lim("knee", self.knee[s]);
            self.ankle[s] = lim("ankle", self.ankle[s]);
            self.shoulder_abd[s] = lim("shoulder_abd", self.shoulder_abd[s]);
            self.shoulder_flex[s] = lim("shoulder_flex", self.shoulder_flex[s]);
            self.shoulder_across[s] = lim("shoulder_across", self.shoulder_across[s]);
            self.elbow[s] = lim("elbow", self.elbow[s]);
            self.forearm_twist[s] = lim("forearm_twist", self.forearm_twist[s]);
            self.wrist_flex[s] = lim("wrist_flex", self.wrist_flex[s]);
            self.wrist_dev[s] = lim("wrist_dev", self.wrist_dev[s]);
            self.finger_curl[s] = lim("finger_curl", self.finger_curl[s]);
        }
        self
    }
}

/// A seeded procedural motion: angles as a function of time.
#[derive(Debug, Clone)]
pub struct Procedural {
    pub style: Style,
    pub period_s: f32,
    amp: f32,
    phase: f32,
    side: usize,
    jitter: [f32; 4],
    seed: u64,
    hands: Option<HandDraw>,
}

impl Procedural {
    pub fn new(style: Style, seed: u64, period_s: f32) -> Self {
        let mut r = ChaCha8Rng::seed_from_u64(seed);
        Self {
            style,
            period_s: period_s.max(0.1),
            amp: r.random_range(0.85..1.15),
            phase: r.random_range(0.0..1.0),
            side: r.random_range(0..2),
            jitter: [
                r.random_range(-1.0..1.0),
                r.random_range(-1.0..1.0),
                r.random_range(-1.0..1.0),
                r.random_range(-1.0..1.0),
            ],
            seed,
            hands: None,
        }
    }

    /// The same motion with its hands posed as `hands` says (drawn from the seed's own
    /// stream: the body's angles do not change).
    pub fn with_hands(mut self, hands: Hands) -> Self {
        self.hands = match hands {
            Hands::Rest => None,
            Hands::Varied => Some(HandDraw::new(self.seed)),
        };
        self
    }

    /// How the hands are posed.
    pub fn hands(&self) -> Hands {
        if self.hands.is_some() {
            Hands::Varied
        } else {
            Hands::Rest
        }
    }

    /// Angles at time `t` seconds, limits applied.
    pub fn angles(&self, t: f32) -> Angles {
        let ph = std::f32::consts::TAU * (t / self.period_s + self.phase);
        let (a, j) = (self.amp, self.jitter);
        let mut g = Angles {
            shoulder_abd: [-10.0, -10.0],
            elbow: [10.0, 10.0],
            ..Default::default()
        };
        match self.style {
            Style::Walk => {
                let s = ph.sin();
                g.hip_flex = [25.0 * a * s, -25.0 * a * s];
                g.knee = [30.0 * a * (1.0 - s).max(0.0), 30.0 * a * (1.0 + s).max(0.0)];
                g.shoulder_flex = [-20.0 * a * s, 20.0 * a * s];
                g.elbow = [20.0 + 10.0 * j[0], 20.0 + 10.0 * j[1]];
                g.spine_flex = 4.0;
            }
            Style::ArmsRaised => {
                let up = 140.0 + 10.0 * j[0] + 6.0 * ph.sin();
                g.shoulder_abd = [up, up + 8.0 * j[1]];
                g.elbow = [15.0 + 10.0 * j[2], 15.0];
                g.neck_flex = -15.0;
            }
            Style::Crouch => {
                let c = 0.5 + 0.5 * ph.sin();
                g.hip_flex = [(50.0 + 50.0 * c) * a; 2];
                g.knee = [(60.0 + 60.0 * c) * a; 2];
                g.ankle = [20.0 * c; 2];
                g.spine_flex = 25.0 * c;
                g.shoulder_flex = [40.0 + 20.0 * j[0], 40.0 + 20.0 * j[1]];
            }
            Style::Turn => {
                g.root_yaw = 360.0 * (t / self.period_s + self.phase);
                g.shoulder_abd = [20.0, 20.0];
            }
            Style::ArmAcross => {
                let s = self.side;
                g.shoulder_flex[s] = 80.0 + 10.0 * j[0];
                g.shoulder_across[s] = 60.0 + 15.0 * j[1] + 10.0 * ph.sin();
                g.elbow[s] = 80.0 + 20.0 * j[2];
            }
            Style::Lean => {
                g.spine_side =
                    (25.0 * a) * if self.side == 0 { 1.0 } else { -1.0 } * (0.7 + 0.3 * ph.sin());
                g.spine_flex = 10.0 * j[0];
                g.shoulder_abd = [15.0, 15.0];
            }
        }
        if let Some(h) = &self.hands {
            h.apply(ph, &mut g);
        }
        g.limited()
    }
}

/// Bone indices the generator drives.
#[derive(Debug, Clone)]
pub struct Rig {
    root: Option<usize>,
    spine: Option<usize>,
    neck: Option<usize>,
    upperleg: [Option<usize>; 2],
    lowerleg: [Option<usize>; 2],
    foot: [Option<usize>; 2],
    upperarm: [Option<usize>; 2],
    lowerarm: [Option<usize>; 2],
    /// Rest direction of each upper arm (for abduction relative to the A pose).
    arm_dir: [Vec3; 2],
    hands: HandRig,
    nbones: usize,
}

impl Rig {
    pub fn new(assets: &HumanAssets, heads: &[Vec3]) -> Self {
        let find = |n: &str| assets.bones.iter().position(|b| b.name == n);
        let lr = |base: &str| [find(&format!("{base}.L")), find(&format!("{base}.R"))];
        let upperarm = lr("upperarm01");
        let lowerarm = lr("lowerarm01");
        let mut arm_dir = [
            Vec3::new(1.0, -1.0, 0.0).normalize(),
            Vec3::new(-1.0, -1.0, 0.0).normalize(),
        ];
        for s in 0..2 {
            if let (Some(u), Some(l)) = (upperarm[s], lowerarm[s]) {
                arm_dir[s] = (heads[l] - heads[u]).normalize_or(arm_dir[s]);
            }
        }
        Self {
            root: find("root"),
            spine: find("spine03"),
            neck: find("neck02"),
            upperleg: lr("upperleg01"),
            lowerleg: lr("lowerleg01"),
            foot: lr("foot"),
            upperarm,
            lowerarm,
            arm_dir,
            hands: HandRig::new(assets, heads),
            nbones: assets.bones.len(),
        }
    }

    /// Per-bone rotations for `a`.
    pub fn rotations(&self, a: &Angles, out: &mut Vec<Mat3>) {
        out.clear();
        out.resize(self.nbones, Mat3::IDENTITY);
        let r = |d: f32| d.to_radians();
        let mut set = |b: Option<usize>, m: Mat3| {
            if let Some(b) = b {
                out[b] = m;
            }
        };
        set(self.root, Mat3::from_rotation_y(r(a.root_yaw)));
        set(
            self.spine,
            Mat3::from_rotation_x(r(a.spine_flex)) * Mat3::from_rotation_z(r(a.spine_side)),
        );
        set(self.neck, Mat3::from_rotation_x(r(a.neck_flex)));
        for s in 0..2 {
            let sign = if s == 0 { 1.0 } else { -1.0 };
            set(self.upperleg[s], Mat3::from_rotation_x(-r(a.hip_flex[s])));
            set(self.lowerleg[s], Mat3::from_rotation_x(r(a.knee[s])));
            set(self.foot[s], Mat3::from_rotation_x(-r(a.ankle[s])));
            // Abduction relative to the rest (A) pose: about z, away from the body. Flexion
            // forward about x; across the body about y (toward the other side).
            let abd = Mat3::from_rotation_z(sign * r(a.shoulder_abd[s]));
            let flex = Mat3::from_rotation_x(-r(a.shoulder_flex[s]));
            let across = Mat3::from_rotation_y(-sign * r(a.shoulder_across[s]));
            set(self.upperarm[s], across * flex * abd);
            // Elbow flexes about the axis across the arm and the forward direction, the
            // same sense on both sides: (d x z) x d = z for the rest direction d, so a
            // positive angle brings the forearm forward (+z) on the left and on the right.
            let axis = self.arm_dir[s].cross(Vec3::Z).normalize_or(Vec3::X);
            set(self.lowerarm[s], Mat3::from_axis_angle(axis, r(a.elbow[s])));
        }
        self.hands.rotations(a, out);
    }

    /// Where the palm of side `s` (0 left, 1 right) faces at rest (`hands.rs`; none where the
    /// rig lacks that hand's joints).
    pub fn palm(&self, s: usize) -> Option<Vec3> {
        self.hands.palm(s)
    }
}

/// A named static pose from the pack as per-bone rotations.
pub fn static_pose(assets: &HumanAssets, name: &str, out: &mut Vec<Mat3>) -> Result<(), String> {
    let p = assets.poses.get(name).ok_or_else(|| {
        format!(
            "unknown pose '{name}' (available: rest, {})",
            assets.poses.keys().cloned().collect::<Vec<_>>().join(", ")
        )
    })?;
    out.clear();
    out.extend(assets.bones.iter().map(|b| {
        p.get(&b.name)
            .map(Mat3::from_cols_array)
            .unwrap_or(Mat3::IDENTITY)
    }));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn limits_hold_for_every_style_seed_and_time() {
        for style in Style::ALL {
            for seed in 0..20 {
                let p = Procedural::new(style, seed, 1.3);
                for k in 0..40 {
                    let a = p.angles(k as f32 * 0.097);
                    assert_eq!(a, a.limited(), "{style:?}");
                    assert!(a.knee.iter().all(|k| (0.0..=140.0).contains(k)));
                }
            }
        }
    }

    #[test]
    fn names_are_the_scene_file_names() {
        for st in Style::ALL {
            let parsed: Style = serde_json::from_value(serde_json::json!(st.name())).unwrap();
            assert_eq!(parsed, st);
        }
    }

    /// The default subject, its rig and its vertices' parts, built once per test.
    struct Body {
        assets: crate::assets::HumanAssets,
        subject: crate::subject::Subject,
        rig: Rig,
        parts: Vec<crate::parts::Part>,
    }

    impl Body {
        fn new() -> Self {
            use crate::subject::{Subject, SubjectSpec};
            let assets = crate::assets::HumanAssets::embedded().unwrap();
            let subject = Subject::new(&assets, &SubjectSpec::default()).unwrap();
            let rig = Rig::new(&assets, &subject.heads);
            let parts = crate::parts::vertex_parts(&assets);
            Self {
                assets,
                subject,
                rig,
                parts,
            }
        }

        /// The centroids of `part` (world metres; [left (+x), right]) posed with `a` (the
        /// body's vertices of that part, split by the side they rest on).
        fn centroids(&self, a: &Angles, part: crate::parts::Part) -> [Vec3; 2] {
            let (mut rot, mut posed) = (Vec::new(), crate::subject::Posed::default());
            self.rig.rotations(a, &mut rot);
            self.subject.pose(&self.assets, &rot, &mut posed);
            let mut sum = [(Vec3::ZERO, 0.0f32); 2];
            for (i, p) in self.parts.iter().enumerate() {
                if *p == part {
                    let s = usize::from(self.subject.rest[i].x < 0.0);
                    sum[s].0 += posed.verts[i];
                    sum[s].1 += 1.0;
                }
            }
            sum.map(|(p, n)| p / n.max(1.0))
        }
    }

    /// The angles of the mirror image (x -> -x) of the pose `a`: sides swapped, the yaw and
    /// the side bend negated.
    fn mirrored(a: &Angles) -> Angles {
        let sw = |v: [f32; 2]| [v[1], v[0]];
        Angles {
            root_yaw: -a.root_yaw,
            spine_side: -a.spine_side,
            hip_flex: sw(a.hip_flex),
            knee: sw(a.knee),
            ankle: sw(a.ankle),
            shoulder_abd: sw(a.shoulder_abd),
            shoulder_flex: sw(a.shoulder_flex),
            shoulder_across: sw(a.shoulder_across),
            elbow: sw(a.elbow),
            ..*a
        }
    }

    #[test]
    fn both_elbows_bend_forward() {
        // The character faces +z, its rest arms hang with the elbows a little bent (the
        // forearms forward of the upper arms). Flexing an elbow further brings its hand
        // forward, never behind the body (hyperextension), on either side.
        let body = Body::new();
        let hands = |a: &Angles| body.centroids(a, crate::parts::Part::Hands);
        let rest = hands(&Angles::default());
        let bent = hands(&Angles {
            elbow: [30.0, 30.0],
            ..Default::default()
        });
        for s in 0..2 {
            let dz = bent[s].z - rest[s].z;
            assert!(dz > 0.05, "side {s}: the hand moved {dz} m along +z");
        }
    }

    #[test]
    fn the_rig_is_mirror_symmetric() {
        // A pose and its mirror image put the hands and the feet at mirrored places (x
        // negated, the sides swapped): no joint bends one way on the left and another on
        // the right (the left elbow once bent backward, a chirality every dataset had).
        use crate::parts::Part;
        let body = Body::new();
        for style in Style::ALL {
            for seed in 0..4 {
                let a = Procedural::new(style, seed, 1.3).angles(0.4);
                for part in [Part::Hands, Part::Feet] {
                    let (h, m) = (
                        body.centroids(&a, part),
                        body.centroids(&mirrored(&a), part),
                    );
                    for s in 0..2 {
                        let want = Vec3::new(-h[s].x, h[s].y, h[s].z);
                        let got = m[1 - s];
                        assert!(
                            (got - want).length() < 0.02,
                            "{style:?} seed {seed} {part:?} side {s}: mirror {got} against {want}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn seeded_motion_is_reproducible() {
        let a = Procedural::new(Style::Walk, 7, 1.0).angles(0.3);
        let b = Procedural::new(Style::Walk, 7, 1.0).angles(0.3);
        let c = Procedural::new(Style::Walk, 8, 1.0).angles(0.3);
        assert_eq!(a, b);
        assert_ne!(a, c);
    }
}
