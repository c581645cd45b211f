//! The smallest burn program that runs the kinds of kernel dhrl's learners use, one at a time,
//! on burn's wgpu backend, each result checked against burn's CPU backend (Flex). It names
//! every step before running it, so a crash inside a driver points at its kernel.
//!
//!     cargo run --release --features wgpu-learner --example wgpu_kernels -- gl|vulkan|auto
//!
//! `gl` and `vulkan` pin that graphics API on a CPU adapter (Mesa's llvmpipe / lavapipe on a
//! machine without a GPU); `auto` is `Device::wgpu`'s own choice.
use std::io::Write;

use burn::module::Param;
use burn::nn::{Linear, LinearConfig};
use burn::optim::{AdamConfig, GradientsParams};
use burn::prelude::{Device, DeviceKind, Tensor, TensorData};
use burn::tensor::activation::relu;
use burn::tensor::wgpu::WgpuBackend;

fn device(api: &str) -> Device {
    let api = match api {
        "gl" => WgpuBackend::Gl,
        "vulkan" => WgpuBackend::Vulkan,
        "auto" => return Device::wgpu(DeviceKind::DefaultDevice),
        other => panic!("unknown graphics API {other}; accepted: gl, vulkan, auto"),
    };
    Device::wgpu_options()
        .device_kind(DeviceKind::Cpu)
        .graphics_api(api)
        .init()
        .unwrap_or_else(|e| panic!("no {api:?} adapter: {e}"))
}

fn values<const D: usize>(tensor: Tensor<D>) -> Vec<f32> {
    tensor
        .into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .unwrap()
}

/// Runs `op` on both devices, printing its name first, and compares the results.
fn check(name: &str, gpu: &Device, op: impl Fn(&Device) -> Vec<f32>) {
    print!("{name} ... ");
    std::io::stdout().flush().unwrap();
    let (expected, found) = (op(&Device::flex()), op(gpu));
    let worst = expected
        .iter()
        .zip(&found)
        .map(|(e, f)| (e - f).abs() / e.abs().max(1.0))
        .fold(0.0f32, f32::max);
    assert_eq!(expected.len(), found.len(), "{name}: lengths differ");
    assert!(worst < 1e-4, "{name}: relative error {worst}");
    println!("ok (largest relative error {worst:.1e})");
}

/// A layer with fixed weights (the same on both devices).
fn linear(inputs: usize, outputs: usize, device: &Device) -> Linear {
    let mut layer: Linear = LinearConfig::new(inputs, outputs).init(device);
    layer.weight = Param::from_tensor(input(inputs, outputs, device) * 0.5);
    layer.bias = Some(Param::from_tensor(
        input(1, outputs, device).reshape([outputs]),
    ));
    layer
}

fn input(rows: usize, cols: usize, device: &Device) -> Tensor<2> {
    let values = (0..rows * cols)
        .map(|i| ((i * 37 % 101) as f32 / 50.0) - 1.0)
        .collect::<Vec<_>>();
    Tensor::from_data(TensorData::new(values, [rows, cols]), device)
}

fn main() {
    let api = std::env::args().nth(1).unwrap_or_else(|| "auto".into());
    let gpu = device(&api);
    println!("device: {gpu:?}");
    check("upload and read back", &gpu, |d| values(input(4, 3, d)));
    check("elementwise add and mul", &gpu, |d| {
        values(input(8, 8, d) * 2.0 + input(8, 8, d))
    });
    check("exp, log, tanh", &gpu, |d| {
        values((input(8, 8, d).exp() + 1.0).log().tanh())
    });
    check("sum along a dimension", &gpu, |d| {
        values(input(16, 8, d).sum_dim(1))
    });
    check("mean of all", &gpu, |d| values(input(16, 8, d).mean()));
    check("matmul 4x3 by 3x5", &gpu, |d| {
        values(input(4, 3, d).matmul(input(3, 5, d)))
    });
    check("matmul 256x256 by 256x256", &gpu, |d| {
        values(input(256, 256, d).matmul(input(256, 256, d)))
    });
    check("linear layer and relu", &gpu, |d| {
        let layer = linear(3, 5, d);
        values(relu(layer.forward(input(4, 3, d))))
    });
    check("backward of a two-layer net", &gpu, |d| {
        let train = d.clone().autodiff();
        let first = linear(3, 16, &train);
        let x = input(8, 3, &train);
        let loss = relu(first.forward(x)).powf_scalar(2.0).mean();
        let grads = loss.backward();
        values(first.weight.grad(&grads).unwrap())
    });
    check("one Adam step", &gpu, |d| {
        let train = d.clone().autodiff();
        let layer = linear(3, 4, &train);
        let loss = layer.forward(input(8, 3, &train)).powf_scalar(2.0).mean();
        let grads = GradientsParams::from_grads(loss.backward(), &layer);
        let mut adam = AdamConfig::new().init();
        let layer = adam.step(1e-3, layer, grads);
        values(layer.weight.val().without_autodiff())
    });
    println!("every kernel ran on {api}");
}
