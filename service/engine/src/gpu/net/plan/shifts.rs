//! The shifted-sum upsamplings back into one step. Export writes every bilinear x2 `Resize`
//! as shifted sums for tract (`volcap_train.onnx_rewrite.resize_to_shifts`: per axis four
//! slices, three concatenations, three products, two sums, two unsqueezes and a reshape, 30
//! nodes in all), which on the adapter are 30 dispatches (20 copies, 10 element-wise steps)
//! for what the `Resize` kernel does in one. The planner finds each such group, checks that
//! it is exactly what the rewrite writes (ops, constants, shapes, and that nothing outside
//! reads its inner values), and plans it as one bilinear half-pixel x2 `Resize` (equal to
//! the shifted sums within float rounding: the rewrite's own check, and the per-layer parity
//! test, which compares the group's output with tract's).

use super::{Data, Val};
use std::collections::{HashMap, HashSet};
use tract_onnx::pb::GraphProto;

/// A group of the rewrite: its nodes (graph indices, ascending), the value it upsamples and
/// the value it defines (the replaced `Resize`'s output).
#[derive(Debug)]
pub(super) struct Group {
    pub nodes: Vec<usize>,
    pub input: String,
    pub output: String,
}

/// Finds the groups: made once per graph, asked at each node as the planner reaches it.
pub(super) struct Finder<'g> {
    graph: &'g GraphProto,
    producer: HashMap<&'g str, usize>,
}

impl<'g> Finder<'g> {
    pub fn new(graph: &'g GraphProto) -> Self {
        let producer = graph
            .node
            .iter()
            .enumerate()
            .flat_map(|(i, n)| n.output.iter().map(move |o| (o.as_str(), i)))
            .collect();
        Self { graph, producer }
    }

    /// The group that starts at node `idx` (the rewrite writes each group's nodes in a run
    /// that starts with its first slice), if it is one; `vals`: what the planner knows by
    /// then (the input's shape, the constants).
    pub fn at(&self, idx: usize, vals: &HashMap<String, Val>) -> Option<Group> {
        let n = self.graph.node.get(idx)?;
        let prefix = n
            .output
            .first()
            .and_then(|o| o.strip_suffix("a2_first"))
            .filter(|p| is_prefix(p) && n.op_type == "Slice")?;
        let x = n.input.first()?;
        let shape = match vals.get(x)? {
            Val::Dev { shape, .. } | Val::Const { shape, .. } => shape.clone(),
        };
        group(self.graph, vals, &self.producer, prefix, x, shape)
    }
}

/// `rs<digits>_`, the rewrite's names.
fn is_prefix(p: &str) -> bool {
    p.strip_prefix("rs")
        .and_then(|r| r.strip_suffix('_'))
        .is_some_and(|d| !d.is_empty() && d.bytes().all(|b| b.is_ascii_digit()))
}

fn ints(consts: &HashMap<String, Val>, name: &str) -> Option<Vec<i64>> {
    match consts.get(name)? {
        Val::Const { data, .. } => Some(data.ints()),
        Val::Dev { .. } => None,
    }
}

fn float(consts: &HashMap<String, Val>, name: &str) -> Option<f32> {
    match consts.get(name)? {
        Val::Const {
            data: Data::F(v), ..
        } if v.len() == 1 => Some(v[0]),
        _ => None,
    }
}

fn group(
    graph: &GraphProto,
    consts: &HashMap<String, Val>,
    producer: &HashMap<&str, usize>,
    p: &str,
    x: &str,
    shape: Vec<usize>,
) -> Option<Group> {
    if shape.len() != 4 || shape[2] < 2 || shape[3] < 2 {
        return None;
    }
    let mut nodes = Vec::new();
    let mut src = x.to_string();
    let mut output = String::new();
    for axis in [2usize, 3] {
        let t = format!("{p}a{axis}_");
        let len = shape[axis] as i64;
        let want = |name: &str, op: &str, inputs: &[&str]| -> Option<usize> {
            let i = *producer.get(name)?;
            let m = &graph.node[i];
            (m.op_type == op
                && m.output.len() == 1
                && m.input.len() >= inputs.len()
                && inputs.iter().zip(&m.input).all(|(a, b)| *a == b))
            .then_some(i)
        };
        // The slices: [0, 1), [0, n - 1), [1, n), [n - 1, n) along the axis.
        for (name, start, end) in [
            ("first", 0, 1),
            ("head", 0, len - 1),
            ("tail", 1, len),
            ("last", len - 1, len),
        ] {
            let i = want(&format!("{t}{name}"), "Slice", &[&src])?;
            let m = &graph.node[i];
            let read = |k: usize| m.input.get(k).and_then(|s| ints(consts, s));
            if m.input.len() != 4
                || read(1)? != [start]
                || read(2)? != [end]
                || read(3)? != [axis as i64]
            {
                return None;
            }
            nodes.push(i);
        }
        let cat = |name: &str, a: &str, b: &str, ax: usize| -> Option<usize> {
            let i = want(name, "Concat", &[a, b])?;
            let m = &graph.node[i];
            let along = m.attribute.iter().find(|a| a.name == "axis").map(|a| a.i);
            (m.input.len() == 2 && along == Some(ax as i64)).then_some(i)
        };
        nodes.push(cat(
            &format!("{t}prev"),
            &format!("{t}first"),
            &format!("{t}head"),
            axis,
        )?);
        nodes.push(cat(
            &format!("{t}next"),
            &format!("{t}tail"),
            &format!("{t}last"),
            axis,
        )?);
        let scaled = |name: &str, a: &str, q: f32| -> Option<usize> {
            let i = want(name, "Mul", &[a])?;
            let m = &graph.node[i];
            (m.input.len() == 2 && float(consts, &m.input[1]) == Some(q)).then_some(i)
        };
        nodes.push(scaled(&format!("{t}x3"), &src, 0.75)?);
        for side in ["prev", "next"] {
            nodes.push(scaled(&format!("{t}{side}1"), &format!("{t}{side}"), 0.25)?);
            nodes.push(want(
                &format!("{t}{side}w"),
                "Add",
                &[&format!("{t}x3"), &format!("{t}{side}1")],
            )?);
            let i = want(
                &format!("{t}{side}u"),
                "Unsqueeze",
                &[&format!("{t}{side}w")],
            )?;
            if graph.node[i].input.len() != 2
                || ints(consts, &graph.node[i].input[1])? != [axis as i64 + 1]
            {
                return None;
            }
            nodes.push(i);
        }
        nodes.push(cat(
            &format!("{t}pair"),
            &format!("{t}prevu"),
            &format!("{t}nextu"),
            axis + 1,
        )?);
        // The reshape that interleaves: its output is the next axis's input, or the group's.
        let pair = format!("{t}pair");
        let (i, m) = graph
            .node
            .iter()
            .enumerate()
            .find(|(_, m)| m.op_type == "Reshape" && m.input.first() == Some(&pair))?;
        let mut doubled = shape.clone();
        doubled[2] *= 2;
        if axis == 3 {
            doubled[3] *= 2;
        }
        let target: Vec<i64> = doubled.iter().map(|&v| v as i64).collect();
        if m.input.len() != 2 || ints(consts, &m.input[1])? != target || m.output.len() != 1 {
            return None;
        }
        if axis == 2 && m.output[0] != format!("{t}out") {
            return None;
        }
        nodes.push(i);
        src = m.output[0].clone();
        output = src.clone();
    }
    // Nothing outside the group reads its inner values, and none is a graph output.
    let inner: HashSet<&str> = nodes
        .iter()
        .flat_map(|&i| graph.node[i].output.iter().map(|s| s.as_str()))
        .filter(|o| *o != output)
        .collect();
    let members: HashSet<usize> = nodes.iter().copied().collect();
    let read_outside =
        graph.node.iter().enumerate().any(|(i, m)| {
            !members.contains(&i) && m.input.iter().any(|s| inner.contains(s.as_str()))
        });
    if read_outside || graph.output.iter().any(|o| inner.contains(o.name.as_str())) {
        return None;
    }
    nodes.sort_unstable();
    nodes.dedup();
    (nodes.len() == 30).then_some(Group {
        nodes,
        input: x.to_string(),
        output,
    })
}

#[cfg(test)]
mod tests {
    use super::super::{Kernel, plan};
    use tract_onnx::pb::GraphProto;
    use tract_onnx::prelude::*;

    fn graph(file: &str) -> GraphProto {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../models")
            .join(file);
        tract_onnx::onnx()
            .proto_model_for_path(&path)
            .unwrap()
            .graph
            .unwrap()
    }

    /// The rewrite's groups in the file, by their first slice's name.
    fn groups_in(g: &GraphProto) -> usize {
        g.node
            .iter()
            .filter(|n| n.op_type == "Slice" && n.output[0].ends_with("_a2_first"))
            .count()
    }

    fn resizes(g: &GraphProto, shapes: &[Vec<usize>]) -> (usize, usize) {
        let p = plan(g, shapes, Default::default()).unwrap();
        let r = p
            .steps
            .iter()
            .filter(|s| s.kernel == Kernel::Resize)
            .count();
        (r, p.steps.len())
    }

    #[test]
    fn the_rewrites_upsamplings_plan_as_one_resize_each() {
        for (file, shape) in [
            ("seg.onnx", vec![1, 3, 256, 256]),
            ("shape-fourier-small.fourier.onnx", vec![1, 4, 256, 256]),
        ] {
            let g = graph(file);
            let groups = groups_in(&g);
            assert!(groups >= 3, "{file}: {groups} rewritten upsamplings");
            assert_eq!(g.node.iter().filter(|n| n.op_type == "Resize").count(), 0);
            let (r, steps) = resizes(&g, std::slice::from_ref(&shape));
            assert_eq!(r, groups, "{file}");
            // The same graph with its groups' first slices renamed is planned node by node:
            // 30 nodes (20 copies and 10 element-wise steps) a group where it was one step.
            let mut plain = g.clone();
            for n in &mut plain.node {
                for o in &mut n.output {
                    if let Some(p) = o.strip_suffix("a2_first") {
                        *o = format!("{p}a2_first_renamed");
                    }
                }
                for i in &mut n.input {
                    if let Some(p) = i.strip_suffix("a2_first") {
                        *i = format!("{p}a2_first_renamed");
                    }
                }
            }
            let (r0, steps0) = resizes(&plain, &[shape]);
            assert_eq!(r0, 0, "{file}");
            assert_eq!(
                steps0 - steps,
                groups * 29,
                "{file}: {steps0} -> {steps} steps"
            );
        }
    }

    #[test]
    fn a_group_that_is_not_exactly_the_rewrites_is_planned_node_by_node() {
        let g = graph("shape-fourier-small.fourier.onnx");
        let shape = vec![vec![1, 4, 256, 256]];
        let groups = groups_in(&g);
        let first = g
            .node
            .iter()
            .find(|n| n.op_type == "Slice" && n.output[0].ends_with("_a2_first"))
            .unwrap()
            .output[0]
            .strip_suffix("a2_first")
            .unwrap()
            .to_string();
        // Another weight than the bilinear 3/4.
        let mut weight = g.clone();
        let q3 = weight
            .initializer
            .iter_mut()
            .find(|t| t.name == format!("{first}a2_q3"))
            .unwrap();
        let v = tensor_value(q3);
        assert_eq!(v, 0.75);
        set_value(q3, 0.7);
        assert_eq!(resizes(&weight, &shape).0, groups - 1);
        // An inner value read outside the group (a second reader of the shifted sum).
        let mut read = g.clone();
        let mut extra = read.node[0].clone();
        extra.op_type = "Identity".into();
        extra.attribute.clear();
        extra.input = vec![format!("{first}a2_prevw")];
        extra.output = vec!["outside_reader".into()];
        read.node.push(extra);
        assert_eq!(resizes(&read, &shape).0, groups - 1);
    }

    fn tensor_value(t: &tract_onnx::pb::TensorProto) -> f32 {
        if t.raw_data.is_empty() {
            t.float_data[0]
        } else {
            f32::from_le_bytes(t.raw_data[..4].try_into().unwrap())
        }
    }

    fn set_value(t: &mut tract_onnx::pb::TensorProto, v: f32) {
        if t.raw_data.is_empty() {
            t.float_data[0] = v;
        } else {
            t.raw_data = v.to_le_bytes().to_vec();
        }
    }
}
