//! Proof that the tch/libtorch toolchain works end to end: a small LSTM
//! classifier, trained with Adam on a synthetic sequence task, must cut its
//! loss by a large factor. Seeded and on the CPU, so the run is
//! deterministic; it takes well under a second in release mode.

use tch::nn::{self, Module, OptimizerConfig, RNN};
use tch::{Device, Kind, Tensor};

/// Task: read a random sequence of 8 bits and output the first bit, which
/// the LSTM has to carry to the last step (a memory task an MLP on the last
/// input alone cannot solve).
///
/// It draws from libtorch's process-global generator all along (weights and
/// every batch), so it holds the lock the library takes to seed and build
/// its networks ([`learner::seeding::init_seeded`]) for the whole run: a test
/// that builds a network on another thread meanwhile cannot shift its draws.
#[test]
fn lstm_with_adam_learns_to_recall_the_first_bit() {
    learner::seeding::init_seeded(7, train_and_check);
}

fn train_and_check() {
    let device = Device::Cpu;
    let (seq_len, batch, hidden) = (8_i64, 64_i64, 16_i64);
    let vs = nn::VarStore::new(device);
    let root = vs.root();
    let lstm = nn::lstm(&root / "lstm", 1, hidden, Default::default());
    let head = nn::linear(&root / "head", hidden, 2, Default::default());
    let mut opt = nn::Adam::default().build(&vs, 1e-2).expect("Adam builds");

    let loss_on = |bits: &Tensor| -> Tensor {
        // bits: [B, T] in {0, 1}; the LSTM reads them as [B, T, 1] floats.
        let input = bits.to_kind(Kind::Float).unsqueeze(-1);
        let (output, _) = lstm.seq(&input);
        let last = output.select(1, seq_len - 1);
        let target = bits.select(1, 0);
        head.forward(&last).cross_entropy_for_logits(&target)
    };

    let eval_bits = Tensor::randint(2, [256, seq_len], (Kind::Int64, device));
    let initial = loss_on(&eval_bits).double_value(&[]);
    for _ in 0..300 {
        let bits = Tensor::randint(2, [batch, seq_len], (Kind::Int64, device));
        let loss = loss_on(&bits);
        opt.backward_step(&loss);
    }
    let trained = tch::no_grad(|| loss_on(&eval_bits)).double_value(&[]);
    eprintln!("tch smoke: loss {initial:.4} -> {trained:.4}");
    assert!(
        initial > 0.6,
        "an untrained classifier is near chance (ln 2), got {initial}"
    );
    assert!(
        trained < initial / 20.0,
        "loss should fall by ≥20×: initial {initial:.4}, trained {trained:.4}"
    );
}
