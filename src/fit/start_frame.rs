//! The frame Step 1 starts from, and the order it visits the others in.
//!
//! Step 1 places its Gaussians on one frame (farthest-point sampling, the frame's
//! points as the search's templates) and poses them in the other frames from there,
//! so a part that frame does not show gets no Gaussian of its own: its points in the
//! other frames go to whichever Gaussian is nearest. On full input every frame shows
//! every part and Step 1 starts from frame 0. On occluded input (one camera per
//! frame) it starts from the frame with the most points, the one that shows the
//! most of the surface: on bench-dev occluded, frame 0 of laikago shows 7 of its 13
//! parts (44 % of the other frames' points lie on the 6 it misses), where frame 1
//! shows 12; talos's frame 0 misses 3 parts (20 % of the other frames' points).
//!
//! Frames are then visited away from the start in both directions, each posed from
//! its neighbour in time towards the start (`FrameOrder::track_from`): the start,
//! the later frames in order, then the earlier ones backwards. The result's
//! canonical frame is the start frame (SPEC §6 lets it be any frame).

/// The frame with the most points (the earliest of equals); 0 for no frames.
pub fn most_points(sizes: &[usize]) -> usize {
    sizes
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(&a.0)))
        .map_or(0, |(t, _)| t)
}

/// The order Step 1 visits a sequence's frames in.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FrameOrder {
    /// `order[i]`: the input frame at position i (position 0 is the start frame).
    pub order: Vec<usize>,
}

impl FrameOrder {
    /// Time order from frame 0.
    pub fn identity(k: usize) -> Self {
        FrameOrder {
            order: (0..k).collect(),
        }
    }

    /// From frame `start` (clamped to the sequence): `start`, the later frames in
    /// order, then the earlier ones from `start − 1` back to 0, each tracked from its
    /// neighbour in time towards `start`.
    pub fn from_start(k: usize, start: usize) -> Self {
        if k == 0 {
            return Self::identity(0);
        }
        let s = start.min(k - 1);
        FrameOrder {
            order: (s..k).chain((0..s).rev()).collect(),
        }
    }

    /// Per position, the position whose poses it is searched from: its neighbour in
    /// time towards the start (an earlier position; 0 for position 0).
    pub fn track_from(&self) -> Vec<usize> {
        let s = self.start();
        let mut pos = vec![0; self.order.len()];
        for (i, &t) in self.order.iter().enumerate() {
            pos[t] = i;
        }
        self.order
            .iter()
            .map(|&t| match t.cmp(&s) {
                std::cmp::Ordering::Greater => pos[t - 1],
                std::cmp::Ordering::Less => pos[t + 1],
                std::cmp::Ordering::Equal => 0,
            })
            .collect()
    }

    /// The input frame Step 1 starts from.
    pub fn start(&self) -> usize {
        self.order.first().copied().unwrap_or(0)
    }

    /// `items` (one per input frame) in visiting order.
    pub fn permute<T>(&self, items: Vec<T>) -> Vec<T> {
        let mut slots: Vec<Option<T>> = items.into_iter().map(Some).collect();
        self.order
            .iter()
            .filter_map(|&t| slots.get_mut(t).and_then(Option::take))
            .collect()
    }

    /// `items` in visiting order (one per position) back in input order.
    pub fn unpermute<T>(&self, items: Vec<T>) -> Vec<T> {
        let mut slots: Vec<Option<T>> = std::iter::repeat_with(|| None).take(items.len()).collect();
        for (&t, x) in self.order.iter().zip(items) {
            slots[t] = Some(x);
        }
        slots.into_iter().flatten().collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_frame_with_most_points_starts_and_the_earliest_wins_a_tie() {
        assert_eq!(most_points(&[5, 9, 3, 9]), 1);
        assert_eq!(most_points(&[7]), 0);
        assert_eq!(most_points(&[]), 0);
    }

    #[test]
    fn frames_are_visited_away_from_the_start_each_from_its_neighbour_towards_it() {
        let o = FrameOrder::from_start(5, 2);
        assert_eq!(o.order, vec![2, 3, 4, 1, 0]);
        // 3 from 2 (position 0), 4 from 3, 1 from 2, 0 from 1.
        assert_eq!(o.track_from(), vec![0, 0, 1, 0, 3]);
        assert_eq!(o.start(), 2);
        for (i, &f) in o.track_from().iter().enumerate().skip(1) {
            assert!(f < i, "position {i} tracked from a later one");
            assert_eq!(o.order[i].abs_diff(o.order[f]), 1);
        }
        assert_eq!(FrameOrder::from_start(4, 0), FrameOrder::identity(4));
        assert_eq!(FrameOrder::from_start(3, 9).order, vec![2, 1, 0]);
    }

    #[test]
    fn permuting_and_back_is_the_identity() {
        let o = FrameOrder::from_start(6, 4);
        let items: Vec<String> = (0..6).map(|t| format!("f{t}")).collect();
        let p = o.permute(items.clone());
        assert_eq!(p[0], "f4");
        assert_eq!(o.unpermute(p), items);
    }
}
