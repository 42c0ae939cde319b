//! Vertex comparison d_v (paper eq. 6): 1 for equal labels, 0 otherwise in the paper. Beyond the
//! paper, a configurable similarity for different labels lets a mislabelled object still count
//! as (weaker) evidence.

use crate::scene_graph::LabelId;

/// Similarity of two labels in [0, 1]; 1 on the diagonal.
#[derive(Clone, Debug, PartialEq)]
pub struct LabelSimilarity {
    labels: usize,
    /// Row-major `labels × labels`.
    table: Vec<f64>,
}

impl LabelSimilarity {
    /// The paper's hard comparison: equal labels 1, different labels 0.
    pub fn hard(labels: usize) -> Self {
        Self::uniform(labels, 0.0)
    }

    /// Every pair of different labels has similarity `different` (clamped to [0, 1]).
    pub fn uniform(labels: usize, different: f64) -> Self {
        let different = different.clamp(0.0, 1.0);
        let mut table = vec![different; labels * labels];
        for k in 0..labels {
            table[k * labels + k] = 1.0;
        }
        Self { labels, table }
    }

    /// Overrides one pair (symmetric). Out-of-range labels are ignored.
    pub fn set(&mut self, a: LabelId, b: LabelId, similarity: f64) {
        let (a, b) = (a.0 as usize, b.0 as usize);
        if a < self.labels && b < self.labels && a != b {
            let s = similarity.clamp(0.0, 1.0);
            self.table[a * self.labels + b] = s;
            self.table[b * self.labels + a] = s;
        }
    }

    /// d_v(a, b). Labels outside the table compare as equal-or-nothing.
    pub fn get(&self, a: LabelId, b: LabelId) -> f64 {
        let (i, j) = (a.0 as usize, b.0 as usize);
        if i < self.labels && j < self.labels {
            self.table[i * self.labels + j]
        } else if a == b {
            1.0
        } else {
            0.0
        }
    }

    /// Whether any two different labels have positive similarity.
    pub fn is_soft(&self) -> bool {
        (0..self.labels).any(|i| (0..self.labels).any(|j| i != j && self.table[i * self.labels + j] > 0.0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hard_and_soft_tables() {
        let hard = LabelSimilarity::hard(3);
        assert_eq!(hard.get(LabelId(1), LabelId(1)), 1.0);
        assert_eq!(hard.get(LabelId(1), LabelId(2)), 0.0);
        assert!(!hard.is_soft());
        let mut soft = LabelSimilarity::uniform(3, 0.2);
        soft.set(LabelId(0), LabelId(2), 0.7);
        assert_eq!(soft.get(LabelId(2), LabelId(0)), 0.7);
        assert_eq!(soft.get(LabelId(1), LabelId(0)), 0.2);
        assert_eq!(soft.get(LabelId(7), LabelId(7)), 1.0);
        assert_eq!(soft.get(LabelId(7), LabelId(1)), 0.0);
        assert!(soft.is_soft());
    }
}
