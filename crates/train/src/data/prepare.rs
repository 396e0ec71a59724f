//! The one mapping from a configuration to the supervision it needs: [`TrainingData::prepare`]
//! sets up, on a fresh [`TrainingData`], everything `config` asks for — the flow pairs, the LPIPS
//! network, the sharp or EDI-deblurred training images, the sub-exposure poses and the event
//! counts — and says what it prepared, for the caller to report. The frozen networks are given by
//! the caller, which knows where their weights are.

use super::{Dataset, TrainingData};
use crate::config::{BlurModel, EventPairs, TrainConfig, TrainOn};
use crate::pose::exposure::TrackRules;
use crate::TrainError;

/// The frozen networks some losses read; each must be given when `config` needs it.
#[derive(Default)]
pub struct LossNetworks {
    /// The flow network (`flow_loss`).
    pub flow: Option<flow::SpyNet<f32>>,
    /// The LPIPS network (`lpips_weight > 0`).
    pub lpips: Option<lpips::Lpips<f32>>,
}

/// What [`TrainingData::prepare`] set up.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Preparation {
    /// Training-frame pairs with flow supervision (`flow_loss`).
    pub flow_pairs: Option<usize>,
    /// The perceptual loss's network is in place.
    pub lpips: bool,
    /// Training frames deblurred by EDI (`train_on = edi`); the others keep their observed image.
    pub edi_deblurred: Option<usize>,
    /// Training frames the EDI warm-up deblurred (`edi_warmup > 0`).
    pub edi_warmup: Option<usize>,
    /// The shortest and longest exposure (s) of the frames (`blur_model = exposure`).
    pub exposure_s: Option<(f64, f64)>,
    /// Render pairs the event loss compares (`event_loss`): consecutive training frames, or
    /// consecutive sub-exposure renders, as `config.event_pairs` says.
    pub event_pairs: Option<usize>,
    /// Sub-exposure slices the events modulate (`event_modulation`).
    pub modulated_slices: Option<usize>,
}

impl TrainingData {
    /// Prepares the supervision `config` asks for from `data` (the scene this was made from), with
    /// the frozen `networks` it needs; an error names the missing network or the failed step.
    pub fn prepare(
        &mut self,
        data: &Dataset,
        config: &TrainConfig,
        networks: LossNetworks,
    ) -> Result<Preparation, TrainError> {
        let step = |what: &'static str| {
            move |e: TrainError| TrainError::Prepare {
                what,
                source: Box::new(e),
            }
        };
        let missing = || TrainError::Config("its network was not given".into());
        let mut done = Preparation::default();
        if config.flow_loss {
            let flow_loss = step("the flow loss");
            let net = networks.flow.ok_or_else(missing).map_err(&flow_loss)?;
            self.enable_flow(data, config, net).map_err(flow_loss)?;
            done.flow_pairs = Some(self.flow_pairs.iter().filter(|p| p.is_some()).count());
        }
        if config.lpips_weight > 0.0 {
            let perceptual = step("the perceptual (LPIPS) loss");
            let net = networks.lpips.ok_or_else(missing).map_err(&perceptual)?;
            self.enable_lpips(net).map_err(perceptual)?;
            done.lpips = true;
        }
        match config.train_on {
            TrainOn::Sharp => self
                .use_sharp_images(data)
                .map_err(step("the sharp references"))?,
            TrainOn::Edi => {
                let deblurred = self.use_edi_images(data, config);
                done.edi_deblurred = Some(deblurred.map_err(step("the EDI-deblurred frames"))?);
            }
            TrainOn::Blurred => {}
        }
        if config.edi_warmup > 0 {
            let deblurred = self.enable_edi_warmup(data, config);
            done.edi_warmup = Some(deblurred.map_err(step("the EDI warm-up"))?);
        }
        if config.blur_model == BlurModel::Exposure {
            self.enable_exposure(data, config.subframes, TrackRules::of(config))
                .map_err(step("the exposure model"))?;
            done.exposure_s = Some(data.frames.iter().fold((f64::MAX, 0.0f64), |(a, b), f| {
                (a.min(f.exposure_s), b.max(f.exposure_s))
            }));
        }
        if config.event_loss {
            let events = step("the event-generation loss");
            done.event_pairs = Some(match config.event_pairs {
                EventPairs::Frames => {
                    self.enable_events(data, config).map_err(events)?;
                    self.event_pairs.iter().flatten().count()
                }
                EventPairs::Exposure => {
                    self.enable_exposure_events(data, config).map_err(events)?;
                    self.exposure_events.iter().flatten().flatten().count()
                }
            });
        }
        let modulation = config.event_modulation && config.blur_model == BlurModel::Exposure;
        if modulation && self.exposure_modulation.is_empty() {
            self.enable_exposure_events(data, config)
                .map_err(step("the events' modulation of the exposure"))?;
        }
        done.modulated_slices =
            modulation.then(|| self.exposure_modulation.iter().flatten().flatten().count());
        Ok(done)
    }
}
