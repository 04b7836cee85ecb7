"""The service's settings: one section per owner, read from flat ARMFLEET_* names and options.

Each section is a model beside the code that reads it (`Settings.model_fields` lists them):
the simulation (core/sim/settings.py), the engine (engines/settings.py), the HTTP server
(`ServerSettings`, here: app.py and serving.py read it), access and leases
(core/access/settings.py), persistence (persistence/settings.py), the cameras
(core/cameras/settings.py), Foxglove and the camera recording (surfaces/foxglove/settings.py),
ROS 2 (surfaces/ros/settings.py), the UR controllers' ports (surfaces/ur/settings.py).
Code reads `settings.foxglove.port`; what needs two sections (a world list against the
number of worlds, the render batch's pixel limit, camera names against the scene, whether the
engine steps apart from the cameras) is checked here, on the model that holds both.

Why here, at the top: the composite names every section, and persistence and surfaces rank
above the core, so no lower room may import it; a surface is built from its own section and
the `ServiceFacts` (core/surface.py) that `facts()` makes.

The names users type stay flat: every field is an `ARMFLEET_<NAME>` variable and an
`armfleet serve --<name>` option, `<name>` being the field's `validation_alias` where it has
one (`foxglove_port` for `foxglove.port`), else its name. `Settings(worlds=4, foxglove=True)`
takes flat names too; a section may also be given whole (`Settings(sim=SimSettings(...))`).
Precedence: a `armfleet serve` option the user typed > ARMFLEET_* variable > the default.
"""

from __future__ import annotations

from collections.abc import Mapping
from functools import cache
from typing import Any, Literal, TypeVar

from pydantic import BaseModel, ConfigDict, Field, create_model, model_validator
from pydantic.fields import FieldInfo
from pydantic_settings import (
    BaseSettings,
    EnvSettingsSource,
    PydanticBaseSettingsSource,
    SettingsConfigDict,
)

from service.core.access.settings import AccessSettings
from service.core.cameras.settings import CameraSettings
from service.core.sim.settings import SimSettings
from service.core.sim.worlds import world_list
from service.core.surface import ServiceFacts
from service.engines.settings import EngineSettings
from service.persistence.settings import PersistenceSettings
from service.surfaces.foxglove.settings import CameraRecordSettings, FoxgloveSettings
from service.surfaces.ros.settings import Ros2Settings
from service.surfaces.ur.settings import UrSettings

ENV_PREFIX = "ARMFLEET_"
MAX_RENDER_PIXELS = 1 << 26  # one camera's render batch: colour, depth, rays, ~12 bytes a pixel
M = TypeVar("M", bound=BaseModel)


class ServerSettings(BaseModel):
    """The HTTP server (`--host`, `--port`, `--max-body-bytes`, `--ws-compression`,
    `--log-level`): read by app.py and serving.py, which rank with this module."""

    model_config = ConfigDict(extra="forbid")

    host: str = Field("127.0.0.1", description="bind address (loopback by default)")
    port: int = Field(8000, ge=0, le=65535, description="TCP port")
    max_body_bytes: int = Field(1 << 20, description="larger request bodies get 413")
    ws_compression: bool = Field(
        False,
        description="permessage-deflate on WebSockets (off: a 34 KB float32 pose frame costs "
        "milliseconds to deflate, per socket, and shrinks by 7%)",
    )
    log_level: Literal["debug", "info", "warning", "error"] = Field(
        "info", description="debug, info, warning or error"
    )


class Settings(BaseSettings):
    """Every setting of `armfleet serve`, by section (see the module docstring)."""

    model_config = SettingsConfigDict(env_prefix=ENV_PREFIX, extra="forbid")

    sim: SimSettings = Field(default_factory=SimSettings)
    engine: EngineSettings = Field(default_factory=EngineSettings)
    server: ServerSettings = Field(default_factory=ServerSettings)
    access: AccessSettings = Field(default_factory=AccessSettings)
    persistence: PersistenceSettings = Field(default_factory=PersistenceSettings)
    cameras: CameraSettings = Field(default_factory=CameraSettings)
    foxglove: FoxgloveSettings = Field(default_factory=FoxgloveSettings)
    ros2: Ros2Settings = Field(default_factory=Ros2Settings)
    camera_record: CameraRecordSettings = Field(default_factory=CameraRecordSettings)
    ur: UrSettings = Field(default_factory=UrSettings)

    @classmethod
    def settings_customise_sources(
        cls,
        settings_cls: type[BaseSettings],
        init_settings: PydanticBaseSettingsSource,
        env_settings: PydanticBaseSettingsSource,
        dotenv_settings: PydanticBaseSettingsSource,
        file_secret_settings: PydanticBaseSettingsSource,
    ) -> tuple[PydanticBaseSettingsSource, ...]:
        """Keywords first, then the flat ARMFLEET_* variables, each nested into sections (no
        .env file or secrets directory was ever read, so none is now)."""
        return (_Nested(settings_cls, init_settings), _FlatEnvironment(settings_cls))

    @model_validator(mode="before")
    @classmethod
    def _flat_names_into_sections(cls, data: Any) -> Any:
        """`Settings.model_validate({"worlds": 4})` nests too (the sources do it otherwise)."""
        return nest(data) if isinstance(data, Mapping) else data

    @model_validator(mode="after")
    def _world_lists_exist(self) -> Settings:
        world_list(self.ros2.worlds, self.sim.worlds, "ros2_worlds")  # names the bad part
        if self.ur.worlds:
            world_list(self.ur.worlds, self.sim.worlds, "ur_worlds")
        if self.camera_record.path:
            world_list(self.camera_record.worlds, self.sim.worlds, "camera_record_worlds")
        return self

    @model_validator(mode="after")
    def _render_batch_fits(self) -> Settings:
        biggest = self.cameras.largest_pixels()
        if biggest * min(self.cameras.batch, self.sim.worlds) > MAX_RENDER_PIXELS:
            raise ValueError(
                f"camera_batch: {self.cameras.batch} worlds of {biggest} pixels is over the "
                f"render batch's limit of {MAX_RENDER_PIXELS} pixels (~12 bytes each): "
                "lower --camera-batch or the size"
            )
        return self

    @model_validator(mode="after")
    def _cameras_exist(self) -> Settings:
        """Every camera a setting names is one the (default) scene has."""
        from service.core.cameras.catalog import scene_cameras

        asked = {
            "cameras": self.cameras.named(),
            "foxglove_cameras": _names(self.foxglove.cameras),
            "ros2_cameras": _names(self.ros2.cameras),
            "camera_record_cameras": _names(self.camera_record.cameras),
        }
        have = scene_cameras()
        for setting, names in asked.items():
            unknown = [n for n in names if n not in have]
            if unknown:
                raise ValueError(
                    f"{setting}: the scene has no camera {unknown[0]!r} (it has: {', '.join(have)})"
                )
        return self

    def engine_apart(self) -> bool:
        """Whether the warp engine steps in a worker process of its own (engine + cameras:
        `EngineSettings.apart`)."""
        return self.engine.apart(self.cameras.device)

    def section(self, model: type[M]) -> M:
        """The section whose model is `model` (the surface registry asks for its own this way,
        never importing this module)."""
        for name, field in type(self).model_fields.items():
            if field.annotation is model:
                return getattr(self, name)  # type: ignore[no-any-return]
        raise KeyError(f"no settings section of type {model.__name__}")

    def facts(self) -> ServiceFacts:
        """What every surface is told of the service when it is built."""
        return ServiceFacts(
            self.server.host, self.server.port, self.sim.worlds, self.access, self.cameras.rate
        )


def _names(text: str) -> list[str]:
    return [p.strip() for p in text.split(",") if p.strip()]


@cache
def flat_fields() -> dict[str, tuple[str, str, FieldInfo]]:
    """flat name → (section, field, the field's FieldInfo), in the order of the sections: the
    names of the ARMFLEET_* variables and `serve` options (cli.py and the reference page)."""
    out: dict[str, tuple[str, str, FieldInfo]] = {}
    for section, holder in Settings.model_fields.items():
        model = holder.annotation
        assert isinstance(model, type) and issubclass(model, BaseModel)
        for name, field in model.model_fields.items():
            flat = field.validation_alias if isinstance(field.validation_alias, str) else name
            assert flat not in out, f"two settings are both {flat!r}"
            out[flat] = (section, name, field)
    return out


def nest(data: Mapping[str, Any]) -> dict[str, Any]:
    """Flat names into their sections: {"foxglove_port": 1} → {"foxglove": {"port": 1}}. A key
    that names a section and holds a mapping or a model is that section (`foxglove=True` is the
    flat setting, `foxglove={...}` the section); a flat name given beside its whole section
    overrides that field of it."""
    flat = flat_fields()
    out: dict[str, Any] = {}
    loose: list[tuple[str, Any]] = []
    for key, value in data.items():
        if key in Settings.model_fields and isinstance(value, Mapping | BaseModel):
            out[key] = value.model_dump() if isinstance(value, BaseModel) else dict(value)
        else:
            loose.append((key, value))
    for key, value in loose:
        if key not in flat:
            out[key] = value  # not a setting: `extra="forbid"` names it
            continue
        section, name, _ = flat[key]
        out.setdefault(section, {})[name] = value
    return out


def flat_name(loc: tuple[int | str, ...]) -> str:
    """The flat name (what the user typed) of a validation error's location: ("sim",
    "control_hz") → "control_hz"; a whole section's own check → "" (its message names the
    setting)."""
    if len(loc) >= 2:
        for flat, (section, name, _) in flat_fields().items():
            if loc[0] == section and loc[1] in (name, flat):
                return flat
    if len(loc) == 1 and loc[0] in Settings.model_fields:
        return ""
    return ".".join(str(x) for x in loc)


class _Nested(PydanticBaseSettingsSource):
    """A source's flat names nested into sections (see `nest`)."""

    def __init__(self, settings_cls: type[BaseSettings], inner: PydanticBaseSettingsSource):
        super().__init__(settings_cls)
        self.inner = inner

    def get_field_value(self, field: FieldInfo, field_name: str) -> tuple[Any, str, bool]:
        return None, field_name, False  # unused: __call__ reads the inner source whole

    def __call__(self) -> dict[str, Any]:
        return nest(self.inner())


@cache
def _flat_model() -> type[BaseSettings]:
    """The flat fields as one model, only for pydantic-settings to read the variables as it
    always did (ARMFLEET_<NAME>, any case; JSON for a list such as ARMFLEET_ALLOW_ORIGINS)."""
    fields: dict[str, Any] = {
        flat: (field.annotation, None) for flat, (_, _, field) in flat_fields().items()
    }
    return create_model("FlatSettings", __base__=BaseSettings, **fields)  # type: ignore[no-any-return]


class _FlatEnvironment(PydanticBaseSettingsSource):
    """The ARMFLEET_* variables, read by their flat names and nested into sections."""

    def get_field_value(self, field: FieldInfo, field_name: str) -> tuple[Any, str, bool]:
        return None, field_name, False  # unused: __call__ reads every variable at once

    def __call__(self) -> dict[str, Any]:
        read = EnvSettingsSource(_flat_model(), env_prefix=ENV_PREFIX)
        return nest(read())
