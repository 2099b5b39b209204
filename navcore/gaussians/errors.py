"""The one error type for unusable scene input."""


class SceneFormatError(ValueError):
    """A scene file cannot be used. The message names the file and says what is wrong."""

    def __init__(self, path, problem: str, scene_id: str | None = None):
        self.path = str(path)
        self.problem = problem
        self.scene_id = scene_id
        where = f"scene '{scene_id}' ({self.path})" if scene_id else f"{self.path}"
        super().__init__(f"{where}: {problem}")


class SceneFileNotFoundError(SceneFormatError, FileNotFoundError):
    """A scene's source file (or folder) does not exist: "file not found", naming it and the scene."""

    def __init__(self, path, scene_id: str | None = None):
        SceneFormatError.__init__(self, path, "file not found (check the catalog entry's path; relative paths are "
                                  "relative to the catalog file's folder)", scene_id)
