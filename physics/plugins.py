"""The plugin API's old home, kept for plugins written against it: see :mod:`steplab.core.registry`."""

from steplab.core.registry import BUILTIN as BUILTIN
from steplab.core.registry import GROUPS as GROUPS
from steplab.core.registry import PluginError as PluginError
from steplab.core.registry import PluginWarning as PluginWarning
from steplab.core.registry import Registry as Registry
from steplab.core.registry import UnknownNameError as UnknownNameError
from steplab.core.registry import entry_point_origin as entry_point_origin
from steplab.core.registry import import_object as import_object
