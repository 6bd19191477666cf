//! Editing a model by hand (`gsart::edit`): Steps 2–3 done again on a given
//! segmentation, and parts joined into one.
//!
//! Both start from a procedural object's ground truth written as a result (its true
//! labels and poses), so what is checked is Steps 2–3 and the edit, not Step 1.

use gsart::edit::{apply, join_map, Edit};
use gsart::io::result::FitResult;
use gsart::pipeline::{evaluate, Control};
use gsart::synth::{generate, ObjectKind, SynthOptions, SynthOutput};

fn truth(kind: ObjectKind, seed: u64) -> (SynthOutput, FitResult) {
    let out = generate(&SynthOptions {
        seed,
        ..SynthOptions::new(kind)
    })
    .expect("generate");
    let labels = out
        .sequence
        .frames
        .iter()
        .map(|f| f.labels.clone().expect("labels"))
        .collect();
    let r = FitResult::from_ground_truth(&out.gt, labels, 0).expect("truth");
    (out, r)
}

fn clock() -> f64 {
    0.0
}

/// `edit::apply` with joins only.
fn join_parts(
    seq: &gsart::io::sequence::Sequence,
    r: &FitResult,
    groups: &[Vec<usize>],
    clock: &dyn Fn() -> f64,
    cb: &mut dyn FnMut(&gsart::pipeline::Progress) -> Control,
) -> gsart::Result<gsart::pipeline::FitOutput> {
    let edit = Edit {
        join: groups.to_vec(),
        ..Default::default()
    };
    apply(seq, r, &edit, clock, cb)
}

/// With the true segmentation and part poses but no tree, Steps 2–3 find the arm's
/// tree and all six hinges within issue #4's bar (axis ≤ 5°, pivot ≤ 2 %): what the
/// procedural targets miss comes from Step 1's segmentation.
#[test]
fn steps_2_3_on_the_true_segmentation_find_every_hinge() {
    let (out, mut r) = truth(ObjectKind::Arm, 0);
    r.tree = None;
    r.joints = None;
    r.root_motion = None;
    let edited =
        join_parts(&out.sequence, &r, &[], &clock, &mut |_| Control::Continue).expect("Steps 2–3");
    let m = evaluate(&edited.result, &out.sequence, &out.gt).expect("evaluate");
    let j = m.joints.as_ref().expect("joint errors");
    eprintln!("{}", m.summary());
    assert_eq!(m.tree_edit_distance, Some(0), "{m:?}");
    assert_eq!((j.joints, j.found, j.within_bar), (6, 6, 6), "{j:?}");
    assert!(m.mean_ri > 0.95, "{m:?}");
}

/// Joining a knee's two links contracts the quadruped's tree there and nowhere else:
/// the root stays, every other joint keeps its parent, its child and its type, and
/// the other legs' hinges stay within the bar.
#[test]
fn joining_a_joint_contracts_the_tree_there() {
    let (out, r) = truth(ObjectKind::Quadruped, 0);
    let tree = r.tree.clone().expect("tree");
    // A knee: a joint whose child has no children of its own, and whose parent is not
    // the root.
    let is_parent = |p: usize| tree.parent.contains(&(p as i64));
    let knee = r
        .joints
        .as_ref()
        .expect("joints")
        .iter()
        .find(|j| !is_parent(j.child) && j.parent != tree.root)
        .expect("a knee")
        .clone();
    let groups = vec![vec![knee.parent, knee.child]];
    let (map, parts) = join_map(r.parts, &groups).expect("join map");
    assert_eq!(parts, r.parts - 1);
    let edited = join_parts(&out.sequence, &r, &groups, &clock, &mut |_| {
        Control::Continue
    })
    .expect("edit")
    .result;
    assert_eq!(edited.parts, parts);
    let new_tree = edited.tree.as_ref().expect("tree");
    assert_eq!(new_tree.root, map[tree.root] as usize);
    for (p, &parent) in tree.parent.iter().enumerate() {
        if p == knee.child || parent < 0 {
            continue;
        }
        assert_eq!(
            new_tree.parent[map[p] as usize], map[parent as usize] as i64,
            "part {p}"
        );
    }
    // Every input point keeps its part, joined, but for the few near a joint that the
    // relabelling (full input, `kinematics::relabel`) gives to the neighbouring part.
    for (old, new) in r.labels.iter().zip(&edited.labels) {
        let moved = old
            .iter()
            .zip(new)
            .filter(|(&a, &b)| map[a as usize] != b)
            .count();
        assert!(
            moved * 20 < old.len(),
            "{moved} of {} relabelled",
            old.len()
        );
    }
    let m = evaluate(&edited, &out.sequence, &out.gt).expect("evaluate");
    let j = m.joints.as_ref().expect("joint errors");
    eprintln!("{}", m.summary());
    // The joined knee is gone, and its leg's hip now turns a bent leg; the other six
    // hinges are as good as before.
    let others = j
        .per_joint
        .iter()
        .filter(|jm| jm.gt_child != knee.child && jm.gt_child != knee.parent)
        .collect::<Vec<_>>();
    assert_eq!(others.len(), 6);
    for jm in others {
        assert!(jm.within_bar(), "{jm:?}");
    }
    let edits = &edited.info.as_ref().expect("info")["edits"];
    assert_eq!(edits[0]["join"], serde_json::json!(groups));
    assert_eq!(edits[0]["parts_before"], serde_json::json!(r.parts));
}

/// A result edited against frames it was not fitted to, or with joins that name no
/// part, is refused with a message saying so.
#[test]
fn edits_that_cannot_apply_are_refused() {
    let (out, r) = truth(ObjectKind::Laptop, 0);
    let run = |seq: &gsart::io::sequence::Sequence, groups: &[Vec<usize>]| {
        join_parts(seq, &r, groups, &clock, &mut |_| Control::Continue)
            .map(|_| ())
            .map_err(|e| e.to_string())
    };
    let mut fewer = out.sequence.clone();
    fewer.frames.pop();
    assert!(run(&fewer, &[]).unwrap_err().contains("frames"));
    let mut thinner = out.sequence.clone();
    thinner.frames[3].points.truncate(100);
    let e = run(&thinner, &[]).unwrap_err();
    assert!(
        e.contains(&thinner.frames[3].name) && e.contains("100 points"),
        "{e}"
    );
    assert!(run(&out.sequence, &[vec![0, 5]])
        .unwrap_err()
        .contains("part 5 does not exist"));
    assert!(run(&out.sequence, &[vec![1, 1]])
        .unwrap_err()
        .contains("two or more"));
    // Joining everything leaves one part and no joint.
    let all = Edit {
        join: vec![vec![0, 1]],
        ..Default::default()
    };
    let one = apply(&out.sequence, &r, &all, &clock, &mut |_| Control::Continue).expect("one part");
    assert_eq!(one.result.parts, 1);
    assert!(one.result.joints.as_ref().is_none_or(|j| j.is_empty()));
    assert!(one.result.labels.iter().flatten().all(|&l| l == 0));
}

/// A joint type chosen by hand is the type the joint gets, and the other joints keep
/// theirs; choosing the true type again gives the hinge back within the bar. The root
/// has no joint to give a type.
#[test]
fn a_joint_type_chosen_by_hand_is_kept() {
    use gsart::io::gt::JointType;
    let (out, r) = truth(ObjectKind::Cabinet, 0);
    let joints = r.joints.clone().expect("joints");
    let door = joints
        .iter()
        .find(|j| j.joint_type == JointType::Revolute)
        .expect("the door's hinge")
        .child;
    let run = |r: &FitResult, jt: JointType| {
        let edit = Edit {
            joint_types: vec![(door, jt)],
            ..Default::default()
        };
        apply(&out.sequence, r, &edit, &clock, &mut |_| Control::Continue)
    };
    let slid = run(&r, JointType::Prismatic).expect("edit").result;
    let types = |r: &FitResult| -> Vec<(usize, JointType)> {
        let mut t: Vec<_> = r
            .joints
            .iter()
            .flatten()
            .map(|j| (j.child, j.joint_type))
            .collect();
        t.sort_by_key(|x| x.0);
        t
    };
    let expected: Vec<_> = types(&r)
        .into_iter()
        .map(|(c, t)| (c, if c == door { JointType::Prismatic } else { t }))
        .collect();
    assert_eq!(types(&slid), expected);
    let edits = &slid.info.as_ref().expect("info")["edits"];
    assert_eq!(
        edits[0]["joint_types"],
        serde_json::json!([[door, "prismatic"]])
    );
    let back = run(&slid, JointType::Revolute).expect("edit back").result;
    assert_eq!(types(&back), types(&r));
    let m = evaluate(&back, &out.sequence, &out.gt).expect("evaluate");
    let j = m.joints.as_ref().expect("joint errors");
    assert_eq!(j.within_bar, 3, "{j:?}");
    let root = r.tree.as_ref().expect("tree").root;
    let e = apply(
        &out.sequence,
        &r,
        &Edit {
            joint_types: vec![(root, JointType::Prismatic)],
            ..Default::default()
        },
        &clock,
        &mut |_| Control::Continue,
    )
    .map(|_| ())
    .unwrap_err()
    .to_string();
    assert!(e.contains("root"), "{e}");
}

/// A root chosen by hand (a foot of the quadruped, the URDF's base) turns the joints on
/// the way round: the tree is rooted there, and every hinge is still a hinge in the
/// bar (the old joints keep their types).
#[test]
fn a_root_chosen_by_hand_turns_the_tree_round() {
    let (out, r) = truth(ObjectKind::Quadruped, 0);
    let tree = r.tree.clone().expect("tree");
    let foot = (0..r.parts)
        .find(|&p| p != tree.root && !tree.parent.contains(&(p as i64)))
        .expect("a foot");
    let edit = Edit {
        root: Some(foot),
        ..Default::default()
    };
    let edited = apply(&out.sequence, &r, &edit, &clock, &mut |_| Control::Continue)
        .expect("edit")
        .result;
    let new_tree = edited.tree.as_ref().expect("tree");
    assert_eq!(new_tree.root, foot);
    assert_eq!(edited.parts, r.parts);
    // The foot's thigh is now the foot's child, and the body the thigh's.
    let thigh = tree.parent[foot] as usize;
    assert_eq!(new_tree.parent[thigh], foot as i64);
    assert_eq!(new_tree.parent[tree.root], thigh as i64);
    let m = evaluate(&edited, &out.sequence, &out.gt).expect("evaluate");
    let j = m.joints.as_ref().expect("joint errors");
    assert_eq!((j.found, j.type_correct, j.within_bar), (8, 8, 8), "{j:?}");
    let bad = Edit {
        root: Some(r.parts),
        ..Default::default()
    };
    assert!(apply(&out.sequence, &r, &bad, &clock, &mut |_| Control::Continue).is_err());
}

/// The bench-dev panda gripper's two fingers slide together (their true states are
/// equal): Steps 2–3 on its true segmentation and poses find the coupling (URDF
/// `<mimic>`), re-posing with the leader's state alone moves both fingers, and an
/// unlink frees the finger, changes nothing else and keeps it free through a later
/// edit.
#[test]
fn coupled_fingers_are_found_and_can_be_unlinked() {
    use gsart::io::gt::GroundTruth;
    use gsart::io::sequence::Sequence;
    let Some(dir) = ["../shared/bench-dev", "/work/shared/bench-dev"]
        .iter()
        .map(|b| std::path::Path::new(b).join("full/panda_gripper_00"))
        .find(|d| d.join("gt.json").exists())
    else {
        eprintln!("skip: bench-dev not present");
        return;
    };
    let seq = Sequence::from_dir(&dir).expect("frames");
    let text = std::fs::read_to_string(dir.join("gt.json")).expect("gt.json");
    let gt = GroundTruth::from_json(&text, "gt.json").expect("gt");
    let labels = seq
        .frames
        .iter()
        .map(|f| f.labels.clone().expect("labels"))
        .collect();
    let mut r = FitResult::from_ground_truth(&gt, labels, 0).expect("truth");
    r.points = Some(seq.frames[0].points.iter().map(|p| p.to_array()).collect());
    let run = |r: &FitResult, edit: &Edit| {
        apply(&seq, r, edit, &clock, &mut |_| Control::Continue).map(|o| o.result)
    };
    let coupled = run(&r, &Edit::default()).expect("Steps 2–3");
    let joints = coupled.joints.clone().expect("joints");
    assert_eq!(joints.len(), 2);
    let followers: Vec<_> = joints.iter().filter(|j| j.mimic.is_some()).collect();
    assert_eq!(followers.len(), 1, "{joints:?}");
    let (f, m) = (followers[0], followers[0].mimic.unwrap());
    let leader = joints.iter().find(|j| j.child == m.joint).expect("leader");
    assert!(leader.mimic.is_none());
    // The fingers slide in opposite directions, so the axes decide the sign.
    assert!((m.multiplier.abs() - 1.0).abs() < 0.05, "{m:?}");
    assert!(m.offset.abs() < 0.01, "{m:?}");
    let notes = coupled.info.as_ref().unwrap()["notes"].to_string();
    assert!(notes.contains("URDF mimic"), "{notes}");

    // The leader's state alone re-poses both fingers as giving both states does.
    let q = 0.5 * (leader.limits[0] + leader.limits[1]);
    let both: Vec<f64> = joints
        .iter()
        .map(|j| {
            if j.child == f.child {
                m.multiplier * q + m.offset
            } else {
                q
            }
        })
        .collect();
    let alone = gsart::pipeline::articulate(&coupled, &[q], None).expect("leader alone");
    let given = gsart::pipeline::articulate(&coupled, &both, None).expect("both");
    assert_eq!(alone, given);
    let e = gsart::pipeline::articulate(&coupled, &[q, q, q], None).unwrap_err();
    assert!(
        e.to_string()
            .contains("1 without the ones that follow another"),
        "{e}"
    );

    // Unlinked, the finger moves on its own, and stays so through a later edit.
    let unlink = Edit {
        unlink: vec![f.child],
        ..Default::default()
    };
    let free = run(&coupled, &unlink).expect("unlink");
    assert!(free.joints.iter().flatten().all(|j| j.mimic.is_none()));
    let info = free.info.as_ref().unwrap();
    assert_eq!(info["unlinked"], serde_json::json!([f.child]));
    assert!(!info["notes"].to_string().contains("URDF mimic"), "{info}");
    // Nothing else changes: a coupling does not enter the geometry.
    let mut back = free.clone();
    for (j, c) in back.joints.iter_mut().flatten().zip(&joints) {
        j.mimic = c.mimic;
    }
    assert_eq!(back.joints, coupled.joints);
    assert_eq!(
        (&free.labels, &free.poses, &free.tree),
        (&coupled.labels, &coupled.poses, &coupled.tree)
    );
    let again = run(&free, &Edit::default()).expect("a later edit");
    assert!(again
        .joints
        .as_ref()
        .unwrap()
        .iter()
        .all(|j| j.mimic.is_none()));
    // Only a joint that follows another can be unlinked.
    let e = run(&free, &unlink).unwrap_err().to_string();
    assert!(e.contains("does not follow another"), "{e}");
}

/// Labels an earlier edit (or a fit) made motion-consistent are not relabelled again, so
/// an edit that changes nothing keeps every label (relabelling them again made the
/// bench-dev panda's model drift from edit to edit).
#[test]
fn an_edit_keeps_labels_already_made_motion_consistent() {
    let (out, r) = truth(ObjectKind::Arm, 0);
    let run = |r: &FitResult| {
        join_parts(&out.sequence, r, &[], &clock, &mut |_| Control::Continue)
            .expect("Steps 2–3")
            .result
    };
    let first = run(&r);
    assert!(first.info.as_ref().unwrap().get("relabel").is_some());
    let second = run(&first);
    // Relabelled again (as before this change), some of the arm's labels change.
    assert!(second.labels == first.labels, "labels changed");
    assert_eq!(second.info.as_ref().unwrap()["relabel"]["changed"], 0);
}
