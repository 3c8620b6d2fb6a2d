//! The station's simulated world: one tank, the environment of the system, which the
//! pump (E1) acts on and the gauge (R1) senses through their `DriverContext`.

use embodied::*;

/// Tank and pump parameters.
#[derive(Clone, Copy, Debug)]
pub struct TankParams {
    /// Cross-section \[m²\].
    pub area: f64,
    /// Height \[m\]; the level is clamped to [0, height].
    pub height: f64,
    /// Pump flow at full duty \[m³/s\].
    pub max_flow: f64,
    /// Pump time constant \[s\].
    pub pump_tau: f64,
    /// Gauge noise, standard deviation \[m\].
    pub gauge_sigma: f64,
    /// Probability that a gauge reading is garbage (NaN).
    pub gauge_glitch: f64,
}

impl Default for TankParams {
    fn default() -> Self {
        TankParams {
            area: 0.5,
            height: 2.0,
            max_flow: 0.02,
            pump_tau: 0.2,
            gauge_sigma: 0.004,
            gauge_glitch: 0.01,
        }
    }
}

/// The physical state of the tank: the environment that the pump acts on and the
/// gauge senses.
#[derive(Clone, Copy, Debug)]
pub struct Tank {
    /// Parameters.
    pub params: TankParams,
    /// Level \[m\].
    pub level: f64,
    /// Flow into the tank \[m³/s\] (negative: out).
    pub flow: f64,
}

/// The tank at `level`, still: the system's environment
/// (`SystemBuilder::environment`).
pub fn world(params: TankParams, level: f64) -> Tank {
    Tank {
        params,
        level,
        flow: 0.0,
    }
}

/// A small deterministic generator (SplitMix64) for sensor noise.
#[derive(Clone, Debug)]
pub struct Noise(u64);

impl Noise {
    pub fn new(seed: u64) -> Self {
        Noise(seed)
    }
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Standard normal (Box–Muller).
    pub fn normal(&mut self) -> f64 {
        let u1 = self.uniform().max(1e-300);
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

/// `E1`: a reversible pump. Input: duty in [-1, 1]; output: the measured flow.
#[derive(Debug)]
pub struct Pump {
    /// Duty commands that were NaN or outside [-1, 1] (clamped, or zero for NaN).
    pub rejected: u64,
}

#[derive(Debug, Default, Buffers)]
pub struct PumpInput {
    pub duty: In<f64>,
}

#[derive(Debug, Default, Buffers)]
pub struct PumpOutput {
    pub flow: Out<f64>,
}

impl Driver for Pump {
    const KIND: DeviceKind = DeviceKind::Effector;
    type Input = PumpInput;
    type Output = PumpOutput;

    fn step(
        &mut self,
        mut cx: DriverContext<'_>,
        x: &PumpInput,
        y: &mut PumpOutput,
    ) -> Result<(), DriverError> {
        let raw = x.duty.get().copied().unwrap_or(0.0);
        let duty = if raw.is_nan() {
            0.0
        } else {
            raw.clamp(-1.0, 1.0)
        };
        if x.duty.is_new() && duty != raw {
            self.rejected += 1;
        }
        let dt = cx.period.as_secs_f64();
        let tank = cx.environment::<Tank>()?;
        let p = tank.params;
        // Implicit (backward) Euler on the first-order pump lag: stable for any dt.
        tank.flow = (tank.flow + dt / p.pump_tau * duty * p.max_flow) / (1.0 + dt / p.pump_tau);
        let level = tank.level + tank.flow / p.area * dt;
        if level <= 0.0 || level >= p.height {
            // Empty or full: the pump cannot move more liquid.
            tank.flow = 0.0;
        }
        tank.level = level.clamp(0.0, p.height);
        y.flow.set(tank.flow);
        Ok(())
    }
}

/// `R1`: a level gauge with Gaussian noise and occasional garbage readings.
#[derive(Debug)]
pub struct Gauge {
    pub noise: Noise,
}

#[derive(Debug, Default, Buffers)]
pub struct GaugeOutput {
    pub level: Out<f64>,
}

impl Driver for Gauge {
    const KIND: DeviceKind = DeviceKind::Receptor;
    type Input = ();
    type Output = GaugeOutput;

    fn step(
        &mut self,
        mut cx: DriverContext<'_>,
        _: &(),
        y: &mut GaugeOutput,
    ) -> Result<(), DriverError> {
        let tank = *cx.environment::<Tank>()?;
        let reading = if self.noise.uniform() < tank.params.gauge_glitch {
            f64::NAN
        } else {
            tank.level + tank.params.gauge_sigma * self.noise.normal()
        };
        y.level.set(reading);
        Ok(())
    }
}
