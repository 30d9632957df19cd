// flarekit predict: parses options and calls predict::predict (predict/prediction.h).
#include <iostream>
#include <memory>

#include "app/commands.h"
#include "common/error.h"
#include "common/log.h"
#include "model/flare_model.h"
#include "predict/prediction.h"
#include "predict/scene.h"

namespace flarekit::app {

void registerPredictCommands(CLI::App& app) {
  struct Options {
    std::string model, scene, out, estimator = "mean";
    predict::PredictOptions predict;
  };
  auto o = std::make_shared<Options>();
  auto* cmd = app.add_subcommand(
      "predict", "Predict a scene's lens flare from a fitted model: overlay.exr, composite.png, "
                 "estimators.json and report.html in --out");
  cmd->add_option("MODEL", o->model, "Fitted flare model (model.json)")->required();
  cmd->add_option("--scene", o->scene, "Scene: flarekit.scene JSON, or glTF 2.0 (.gltf/.glb) with "
                                       "KHR_lights_punctual and exposure in camera.extras")
      ->required();
  cmd->add_option("--out", o->out, "Output folder (created if missing)")->required();
  cmd->add_option("--width", o->predict.image_width_px, "Image width in pixels (0: the model's capture width)")
      ->capture_default_str();
  cmd->add_option("--capture-illuminance", o->predict.capture_illuminance_lux,
                  "l·α of the capture's light at the lens, lux (Walch 2018 Eq. 2); 0 = the value the model "
                  "records (from the rig's light_illuminance_lux)")
      ->capture_default_str();
  cmd->add_option("--severity", o->estimator,
                  "Estimator for ranking, map and timeline: min, max, sum, mean, log_average_ratio, "
                  "contrast_ratio")
      ->capture_default_str();
  cmd->add_option("--map-angles", o->predict.map_angle_steps, "Severity map rings (θ steps)")->capture_default_str();
  cmd->add_option("--map-rolls", o->predict.map_roll_steps, "Severity map sectors (φ steps)")->capture_default_str();
  cmd->callback([o] {
    if (!predict::parseEstimator(o->estimator, &o->predict.severity_estimator))
      throw InputError("--severity: unknown estimator \"" + o->estimator + "\"");
    std::string error;
    if (!o->predict.IsValid(&error)) throw InputError("predict: " + error);
    const model::FlareModel model = model::FlareModel::load(o->model);
    const predict::Scene scene = predict::loadScene(o->scene);
    const predict::PredictionSummary s = predict::predict(model, scene, o->predict, o->out, o->model);
    logInfo(s.BriefReport());
    std::cout << (std::filesystem::path(o->out) / "report.html").string() << "\n";
  });
}

}  // namespace flarekit::app
