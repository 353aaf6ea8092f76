"""A Hydra config source serving the plugin registry (``robot``, ``estimator``, ``cost``) and the
scenario presets (``scenario``) as config groups.

Hydra asks a config source three things: which groups and options exist (answered from installed
metadata, :func:`idkit.registry.available`, no import) and the content of one option (answered by
importing that plugin only and reading its constructor, :func:`idkit.cli.nodes.plugin_node`). So a
run imports just the plugins it selects, and a distribution installed tomorrow is selectable by
name with no YAML. YAML files in ``conf/<group>/`` come earlier on the search path and win.

The ``scenario`` group is :data:`idkit.data.presets.SCENARIOS` (torch-free): ``+scenario=outliers``
is the node ``{name: outliers, state_noise: 0.05, ...}`` with the preset's values, each
overridable (``scenario.torque_noise=0.1``); the number of samples is the top-level ``n_samples``.
"""

from __future__ import annotations

from typing import ClassVar

from hydra.core.config_search_path import ConfigSearchPath
from hydra.core.object_type import ObjectType
from hydra.errors import ConfigCompositionException
from hydra.plugins.config_source import ConfigResult, ConfigSource
from hydra.plugins.search_path_plugin import SearchPathPlugin
from omegaconf import OmegaConf

from idkit import registry
from idkit.cli.nodes import plugin_node

SCHEME = "idkit"
SEARCH_PATH = f"{SCHEME}://registry"
PLUGIN_GROUPS: tuple[registry.Kind, ...] = ("robot", "estimator", "cost")
SCENARIO_GROUP = "scenario"
GROUPS = (*PLUGIN_GROUPS, SCENARIO_GROUP)
#: Scenario fields not in the config node: the label, and ``n_samples`` (the top-level knob).
SCENARIO_HIDDEN = ("description", "n_samples")


def group_options(group: str) -> list[str]:
    """The option names of a registry or scenario group (installed metadata, no plugin import)."""
    if group == SCENARIO_GROUP:
        from idkit.data.presets import SCENARIOS

        return list(SCENARIOS)
    return list(registry.available(group))  # type: ignore[arg-type]  # a config's string; checked there


def scenario_node(name: str) -> dict[str, object]:
    """The config node of a scenario preset: its fields and values, but for ``SCENARIO_HIDDEN``."""
    from idkit.data.presets import SCENARIOS

    return {k: v for k, v in SCENARIOS[name].as_dict().items() if k not in SCENARIO_HIDDEN}


class RegistryConfigSource(ConfigSource):
    """Config source for the search-path entry ``idkit://registry``."""

    #: Serve ``{_name_: ...}`` only, without importing plugins (set for ``--help``).
    names_only: ClassVar[bool] = False

    @staticmethod
    def scheme() -> str:
        return SCHEME

    def available(self) -> bool:
        return True

    @staticmethod
    def _split(config_path: str) -> tuple[str, str]:
        path = config_path.strip("/")
        if path.endswith(".yaml"):
            path = path[: -len(".yaml")]
        group, _, name = path.partition("/")
        return group, name

    def is_group(self, config_path: str) -> bool:
        group, name = self._split(config_path)
        return name == "" and (group == "" or group in GROUPS)

    def is_config(self, config_path: str) -> bool:
        group, name = self._split(config_path)
        return group in GROUPS and "/" not in name and name in group_options(group)

    def list(self, config_path: str, results_filter: ObjectType | None) -> list[str]:
        group, name = self._split(config_path)
        if name:
            return []
        if group == "":
            return list(GROUPS) if results_filter in (None, ObjectType.GROUP) else []
        if group in GROUPS and results_filter in (None, ObjectType.CONFIG):
            return sorted(group_options(group))
        return []

    def load_config(self, config_path: str) -> ConfigResult:
        group, name = self._split(config_path)
        try:
            if group == SCENARIO_GROUP:
                node = scenario_node(name)
            else:
                node = plugin_node(group, name, names_only=self.names_only)  # type: ignore[arg-type]  # registry checks it
        except registry.PluginError as exc:
            raise ConfigCompositionException(str(exc)) from exc
        return ConfigResult(
            config=OmegaConf.create(node),
            path=self.full_path(),
            provider=self.provider,
            header={"package": None},
        )


class RegistrySearchPath(SearchPathPlugin):
    """Puts ``idkit://registry`` after ``conf/`` on every search path, so that YAML wins over
    derived nodes and ``--help`` lists the registry groups (a primary config's
    ``hydra.searchpath`` is not consulted when Hydra lists groups)."""

    def manipulate_search_path(self, search_path: ConfigSearchPath) -> None:
        search_path.append(provider="idkit-registry", path=SEARCH_PATH)
