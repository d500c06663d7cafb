//! # planner — the world graph and its traversal
//!
//! Implements the graph side of Shang et al. 2019, *Learning World Graphs to
//! Accelerate Hierarchical Reinforcement Learning* (arXiv:1907.00664),
//! section 3.3: nodes are pivotal states (or any candidate set such as
//! `V_rand`), edges come from random walks that reach another node without
//! touching a third, and traversal between nodes is planned by dynamic
//! programming over the edge weights. The route service answers requests
//! from the learner over iceoryx2.
#![forbid(unsafe_code)]
