//! The recurrent variational model with differentiable binary latent
//! variables that discovers pivotal states (Shang et al. 2019,
//! arXiv:1907.00664, section 3.1).

pub mod beta_prior;
pub mod hardkuma;
